"""The final penetration check: no result is reported with a hair particle inside the body.

Every method that claims a penetration-free result (the solvers, the baselines with
``+pushout``) ends here (:func:`resolve_penetration`): the non-root particles inside the
body are counted by its inside test (the winding number, :mod:`.inside`, the same test as
the penetration metrics); any found are pushed out (:func:`.clearance.push_inside_out`) and
reported; if some are still inside after that, the result is refused with
:class:`~hairport.solver.model.errors.PenetrationRemaining` (code ``penetration_remaining``).
Then the segments between particles outside that pass through the body
(:mod:`.segment_crossing`; the solvers clear theirs, :mod:`hairport.solver.adaptation.segments`):
any found have their ends pushed away along the normal at their deepest point
(:func:`resolve_crossings`), and a result that keeps one is refused the same way.

Convention: particles ``(N, 3) float64`` in meters.
"""

from __future__ import annotations

import numpy as np

from hairport.solver.mesh.clearance import push_inside_out
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.mesh.segment_crossing import SegmentCrossings, crossing_segments, weld_runs
from hairport.solver.model.errors import PenetrationRemaining


def inside_depths(points: np.ndarray, is_root: np.ndarray, query: MeshQuery,
                  distance: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The non-root particles inside the body and how deep (m) they are.

    Parameters
    ----------
    points : (N, 3) float64
    is_root : (N,) bool
    query : MeshQuery
        The body (its collision surface: the sign of its distance is the inside test).
    distance : (N,) float64, optional
        Every particle's signed distance (roots: anything), when the caller has it.

    Returns
    -------
    rows : (K,) int64
        Particles inside, ascending.
    depth : (K,) float64
        Their distance to the body's surface (m).
    """
    free = np.flatnonzero(~np.asarray(is_root, dtype=bool))
    if distance is not None:
        free_distance = np.asarray(distance, dtype=np.float64)[free]
    else:
        free_distance = query.signed_distance(points[free]).distance if len(free) else np.zeros(0)
    inside = free_distance < 0.0
    return free[inside], -free_distance[inside]


def resolve_penetration(
    points: np.ndarray, is_root: np.ndarray, query: MeshQuery, clearance: float, body: str | None = None,
    distance: np.ndarray | None = None, welded: np.ndarray | None = None,
) -> tuple[np.ndarray, dict]:
    """Push out the particles a method left inside the body, or refuse the result.

    Parameters
    ----------
    points : (N, 3) float64
        A method's result.
    is_root : (N,) bool
        Roots (on the surface by Eq. 12) are not checked.
    query : MeshQuery
        The body's collision surface (:func:`.collision.collision_query`).
    clearance : float
        Meters: where pushed particles land beyond the surface (``eps_c``).
    body : str, optional
        The body's name, for the error.
    distance : (N,) float64, optional
        Every particle's signed distance at ``points`` (roots: anything), when the caller has it.
    welded : (N,) bool, optional
        Particles joined to the next by a degenerate segment: a run of them is pushed as one.

    Returns
    -------
    points : (N, 3) float64
        ``points`` itself when none was inside, else a new array.
    resolved : dict
        ``particles``: how many were inside and were pushed out; ``deepest_m``: the deepest of
        them (0 when none).

    Raises
    ------
    PenetrationRemaining
        Some particles are still inside after the push-out.
    """
    rows, depth = inside_depths(points, is_root, query, distance)
    resolved = {"particles": int(len(rows)), "deepest_m": float(depth.max(initial=0.0))}
    if len(rows) == 0:
        return points, resolved
    runs = None if welded is None else weld_runs(welded)
    pushed, left = push_inside_out(points, _whole_runs(rows, runs, is_root), query, clearance, runs)
    if len(left):
        raise PenetrationRemaining(
            f"{len(left):,} of the {len(rows):,} hair particles the method left inside the target body (deepest "
            f"{1e3 * resolved['deepest_m']:.2f} mm) are still inside after pushing them out (the first: particle "
            f"{left[0]}); no penetration-free result was found",
            body,
        )
    return pushed, resolved


#: rounds at most of moving the segments through the body out of it (each checked again) ...
SEGMENT_PUSH_ROUNDS = 12
#: ... in the first ones a segment that sags into the body has its ends pushed out; after them, its strand's
#: tail is taken back across, as for a segment through a thin part
PUSH_ONLY_ROUNDS = 4


def push_segment_ends(points: np.ndarray, segments: np.ndarray, is_root: np.ndarray, crossings: SegmentCrossings,
                      clearance: float, welded: np.ndarray | None = None) -> np.ndarray:
    """Move the free ends of crossing segments so that each one's deepest point would sit out of the body.

    Each end goes along the outward normal at its segment's deepest point, by the depth over its lever
    (:meth:`.segment_crossing.SegmentCrossings.levers`) plus the clearance; an end of several crossing
    segments takes, per axis, the largest push each way (not their sum).

    Parameters
    ----------
    points : (N, 3) float64
    segments : (M, 2) int64
    is_root : (N,) bool
    crossings : SegmentCrossings
        Over ``segments``.
    clearance : float
        Meters.
    welded : (N,) bool, optional
        Particles that start a degenerate segment (:attr:`~hairport.solver.model.hair.Hair.short_segments`):
        each run of particles joined by such segments moves as one.

    Returns
    -------
    points : (N, 3) float64
        A new array.
    """
    ends, crossing, lift = crossings.end_lifts(segments, is_root, clearance)
    push = lift[:, None] * crossings.normal[crossing]
    out = np.array(points, dtype=np.float64)
    run = weld_runs(welded) if welded is not None and np.any(welded) else None
    # the pushes of the few ends (or of their weld runs), not arrays over every particle
    moving, slot = np.unique(ends if run is None else run[ends], return_inverse=True)
    up, down = np.zeros((len(moving), 3)), np.zeros((len(moving), 3))
    np.maximum.at(up, slot, np.maximum(push, 0.0))
    np.minimum.at(down, slot, np.minimum(push, 0.0))
    members = moving if run is None else np.flatnonzero(np.isin(run, moving))
    slot = np.searchsorted(moving, members if run is None else run[members])
    out[members] = out[members] + up[slot] + down[slot]
    return out


def pull_tails(points: np.ndarray, segments: np.ndarray, is_root: np.ndarray, crossings: SegmentCrossings,
               offsets: np.ndarray, query: MeshQuery, clearance: float) -> tuple[np.ndarray, np.ndarray]:
    """Take the rest of each strand back across the body part its first crossing segment passes through.

    A segment whose ends lie on either side of a thin part (a hand, between particles a centimetre off
    the skin) is not lifted out by moving its ends along a normal: one end would have to go through.
    Here the segment's far end and every particle after it on the strand move by one translation,
    which puts that end ``clearance`` short of where the segment enters the body: the tail keeps its
    shape and the strand reaches the part's near side.

    Parameters
    ----------
    points : (N, 3) float64
    segments : (M, 2) int64
        Root side first.
    is_root : (N,) bool
    crossings : SegmentCrossings
        Over ``segments``.
    offsets : (S + 1,) int64
    query : MeshQuery
    clearance : float
        Meters.

    Returns
    -------
    points : (N, 3) float64
        A new array.
    strands : (T,) int64
        The strands whose tails moved.
    """
    out = np.array(points, dtype=np.float64)
    near, far = segments[crossings.rows, 0], segments[crossings.rows, 1]
    strand = np.searchsorted(offsets, near, side="right") - 1
    # the first crossing segment of each strand: the tail after it moves, later ones with it
    strand, first = np.unique(strand, return_index=True)
    near, far = near[first], far[first]
    keep = ~is_root[far]
    strand, near, far = strand[keep], near[keep], far[keep]
    if len(far) == 0:
        return out, strand
    direction = out[far] - out[near]
    hits = query.first_hits(out[near], direction)
    length = np.linalg.norm(direction, axis=1)
    entry = np.where(hits.hit, np.minimum(hits.distance, length), length)
    reach = np.maximum(entry - clearance, 0.0) / np.maximum(length, 1e-300)
    move = out[near] + reach[:, None] * direction - out[far]
    counts = offsets[strand + 1] - far
    rows = np.repeat(far - np.concatenate([[0], np.cumsum(counts)[:-1]]), counts) + np.arange(counts.sum())
    out[rows] += np.repeat(move, counts, axis=0)
    return out, strand


def distances_after(before: np.ndarray, after: np.ndarray, distance: np.ndarray, is_root: np.ndarray,
                    query: MeshQuery) -> tuple[np.ndarray, np.ndarray]:
    """``distance (N,)`` at ``after (N, 3)``, given it at ``before (N, 3)``: only the free particles that moved are
    queried (a round of the check moves a few strands of the whole hairstyle). A new array, and ``(N,) bool``:
    the particles that moved."""
    moved = np.any(after != before, axis=1) & ~is_root
    distance = distance.copy()
    if moved.any():
        distance[moved] = query.signed_distance(after[moved]).distance
    return distance, moved


def _recheck(points: np.ndarray, segments: np.ndarray, is_root: np.ndarray, query: MeshQuery, distance: np.ndarray,
             crossings: SegmentCrossings, moved: np.ndarray) -> SegmentCrossings:
    """:func:`.segment_crossing.crossing_segments` at ``points`` given ``crossings`` before the particles where
    ``moved (N,) bool`` moved: only the segments with a moved end are cast again (the others have not changed)."""
    touched = np.flatnonzero(moved[segments].any(axis=1))
    kept = crossings.subset(~np.isin(crossings.rows, touched))
    return kept.joined(crossing_segments(points, segments, is_root, query, distance, among=touched))


def _move_out(points: np.ndarray, segments: np.ndarray, is_root: np.ndarray, query: MeshQuery, clearance: float,
              offsets: np.ndarray, welded: np.ndarray | None, runs: np.ndarray | None, crossings: SegmentCrossings,
              distance: np.ndarray, classify: bool) -> tuple[np.ndarray, SegmentCrossings, np.ndarray, np.ndarray,
                                                             np.ndarray]:
    """Up to :data:`SEGMENT_PUSH_ROUNDS` rounds of moving the crossing segments out: pushes for those that sag,
    tail moves for those through a thin part (``classify``: by
    :meth:`~.segment_crossing.SegmentCrossings.through`, else none) and, after :data:`PUSH_ONLY_ROUNDS`,
    for all; particles pushed inside go out again. ``runs``: :func:`.segment_crossing.weld_runs` of ``welded``
    (None without it). ``distance (N,)`` is every particle's signed distance at ``points`` (roots: anything). Returns the points, the crossings and the particles inside after the last
    round, the strands whose tails moved and the signed distances at the returned points."""
    pulled = np.zeros(0, dtype=np.int64)
    inside = np.zeros(0, dtype=np.int64)
    for round_number in range(SEGMENT_PUSH_ROUNDS):
        if crossings.count == 0 and len(inside) == 0:
            break
        late = round_number >= PUSH_ONLY_ROUNDS
        through = (crossings.through(points, segments, query) if classify and not late
                   else np.full(crossings.count, late))
        moved = push_segment_ends(points, segments, is_root, crossings.subset(~through), clearance, welded)
        if through.any():
            moved, strands = pull_tails(moved, segments, is_root, crossings.subset(through), offsets, query,
                                        clearance)
            pulled = np.union1d(pulled, strands)
        distance, changed = distances_after(points, moved, distance, is_root, query)
        points = moved
        inside, _ = inside_depths(points, is_root, query, distance)
        if len(inside):
            pushed, inside = push_inside_out(points, _whole_runs(inside, runs, is_root), query, clearance, runs)
            distance, pushed_out = distances_after(points, pushed, distance, is_root, query)
            points, changed = pushed, changed | pushed_out
        crossings = _recheck(points, segments, is_root, query, distance, crossings, changed)
    return points, crossings, inside, pulled, distance


def _whole_runs(rows: np.ndarray, runs: np.ndarray | None, is_root: np.ndarray) -> np.ndarray:
    """``rows (K,) int64`` and the other free particles welded to them (``runs``: :func:`.segment_crossing.weld_runs`;
    None: no welds): one place, and one push keeps them together."""
    if runs is None or len(rows) == 0:
        return rows
    return np.flatnonzero(np.isin(runs, runs[rows]) & ~is_root)


def resolve_crossings(points: np.ndarray, segments: np.ndarray, is_root: np.ndarray, query: MeshQuery,
                      clearance: float, offsets: np.ndarray, body: str | None = None,
                      distance: np.ndarray | None = None,
                      welded: np.ndarray | None = None) -> tuple[np.ndarray, dict, SegmentCrossings, np.ndarray]:
    """Push away the segments a method left through the body, or refuse the result.

    Rounds of :func:`push_segment_ends` for the segments that sag into the body from one side, and of
    :func:`pull_tails` for those through a thin part
    (:meth:`~.segment_crossing.SegmentCrossings.through`) and, after :data:`PUSH_ONLY_ROUNDS`, for any
    still there, then the particles pushed inside out again (:func:`.clearance.push_inside_out`), until
    neither a particle nor a segment is inside; if that fails, the same from the method's result with
    pushes only until :data:`PUSH_ONLY_ROUNDS` (the order that clears some strands through the hands).

    Parameters
    ----------
    points : (N, 3) float64
        A result with no particle inside (:func:`resolve_penetration`).
    segments : (M, 2) int64
    is_root : (N,) bool
    query : MeshQuery
        The body's collision surface.
    clearance : float
        Meters (``eps_c``).
    offsets : (S + 1,) int64
        The strands' first particles, for the error.
    body : str, optional
        The body's name, for the error.
    distance : (N,) float64, optional
        Each particle's signed distance at ``points`` (roots: anything), when the caller has it.
    welded : (N,) bool, optional
        Particles joined to the next by a degenerate segment: they move together.

    Returns
    -------
    points : (N, 3) float64
        ``points`` itself when no segment crossed, else a new array.
    resolved : dict
        ``segments``: how many crossed; ``deepest_m``: the deepest point of any (0 when none);
        ``tails_moved``: strands whose tails were taken back across a thin part (:func:`pull_tails`).
    crossings : SegmentCrossings
        None cross at the returned points: the last check's (empty) result.
    distance : (N,) float64
        Each particle's signed distance at the returned points (0 at the roots): ``distance`` itself when given
        and nothing moved; only the particles that moved were queried again.

    Raises
    ------
    PenetrationRemaining
        Some segment still passes through the body after :data:`SEGMENT_PUSH_ROUNDS` rounds.
    """
    is_root = np.asarray(is_root, dtype=bool)
    if distance is None:
        free = np.flatnonzero(~is_root)
        distance = np.zeros(len(points))
        distance[free] = query.signed_distance(points[free]).distance if len(free) else 0.0
    distance = np.where(is_root, 0.0, np.asarray(distance, dtype=np.float64))
    crossings = crossing_segments(points, segments, is_root, query, distance)
    resolved = {"segments": crossings.count, "deepest_m": crossings.report(segments, offsets)["deepest_m"],
                "tails_moved": 0}
    if crossings.count == 0:
        return points, resolved, crossings, distance
    runs = None if welded is None else weld_runs(welded)
    # two orders of the same moves, each from the method's result: the first that clears every segment wins
    for classify in (True, False):
        moved, after, inside, pulled, moved_distance = _move_out(points, segments, is_root, query, clearance, offsets,
                                                                 welded, runs, crossings, distance, classify)
        if after.count == 0 and len(inside) == 0:
            resolved["tails_moved"] = int(len(pulled))
            return moved, resolved, after, moved_distance
    crossings = after
    left = crossings.report(segments, offsets)
    raise PenetrationRemaining(
        f"segments of hair still pass through the target body between two particles outside it: {crossings.count:,}, "
        f"after moving the {resolved['segments']:,} the method left there (deepest {1e3 * resolved['deepest_m']:.2f} "
        f"mm) out for {SEGMENT_PUSH_ROUNDS} rounds, twice (the deepest left: strand {left['deepest_strand']}, segment "
        f"{left['deepest_segment']}; {len(inside):,} particles inside); no result that keeps the whole strands out "
        "of the body was found",
        body,
    )
