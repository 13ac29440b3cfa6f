"""Segments of hair that pass through the body between two particles outside it.

A renderer draws each strand as a curve through its particles, so a segment whose ends are outside the body
but whose middle is inside is hair visibly clipping into the skin: the per-particle check cannot see it (the
sagitta of a chord of length L over a surface of radius R is L^2 / 8R: 0.6 mm for 16 mm segments over a 5 cm
shoulder).

Detection is exact for a closed surface: a ray from an end outside the body along the segment first meets the
surface where the segment enters it, so a segment crosses the body when that first hit is closer than the
segment's other end (:func:`crossing_segments`). A segment from a root (on the surface by Eq. 12) is cast from
its other end, towards the root. How deep a crossing segment goes is measured at :data:`DEPTH_SAMPLES` points
along it (the report's figure, not the test).

Convention: particles ``(N, 3) float64`` in meters; segments ``(M, 2) int64`` particle index pairs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hairport.solver.mesh.query import MeshQuery

#: a surface hit closer than this (m) to a segment's end belongs to that end (a root on the scalp, float32
#: round-off of the ray engine), not to the segment's interior
END_TOLERANCE = 1e-6
#: points along a crossing segment whose signed distance gives its depth (the ends excluded)
DEPTH_SAMPLES = 33
#: the smallest share of a lift of a segment's deepest point that its free end takes when the other end
#: is a root (:meth:`SegmentCrossings.levers`): a point next to the root would ask an unbounded lift
MIN_LEVER = 0.1


@dataclass(frozen=True)
class SegmentCrossings:
    """Result of :func:`crossing_segments`.

    Attributes
    ----------
    rows : (K,) int64
        Rows of the segments (of the ``segments`` given) that pass through the body, ascending.
    depth : (K,) float64
        How deep each goes (m, >= 0): the largest depth of its sampled points.
    deepest_point : (K, 3) float64
        Where along each it is deepest.
    deepest_at : (K,) float64
        That point's parameter along the segment, in (0, 1) from its first end.
    normal : (K, 3) float64
        The outward direction of the distance field there.
    """

    rows: np.ndarray
    depth: np.ndarray
    deepest_point: np.ndarray
    deepest_at: np.ndarray
    normal: np.ndarray

    @property
    def count(self) -> int:
        return int(len(self.rows))

    def starts(self, segments: np.ndarray, n_particles: int) -> np.ndarray:
        """(N,) bool: the particles that start a crossing segment (``segments``: the ones these rows index)."""
        mask = np.zeros(n_particles, dtype=bool)
        mask[segments[self.rows, 0]] = True
        return mask

    def levers(self, segments: np.ndarray, is_root: np.ndarray) -> np.ndarray:
        """``(K, 2) float64``: how far the deepest point of each crossing segment moves when its first or second
        end moves by 1 and the other as much: 1 when both are free; next to a root (which stays), the free
        end's share of the segment at that point (at least :data:`MIN_LEVER`); 0 for a root.

        Parameters
        ----------
        segments : (M, 2) int64
            The segments these rows index.
        is_root : (N,) bool
        """
        first, second = segments[self.rows, 0], segments[self.rows, 1]
        lever = np.ones((self.count, 2))
        lever[:, 0] = np.where(is_root[second], np.maximum(1.0 - self.deepest_at, MIN_LEVER), 1.0)
        lever[:, 1] = np.where(is_root[first], np.maximum(self.deepest_at, MIN_LEVER), 1.0)
        lever[is_root[first], 0] = 0.0
        lever[is_root[second], 1] = 0.0
        return lever

    def end_lifts(self, segments: np.ndarray, is_root: np.ndarray,
                  clearance: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """How far each free end of the crossing segments must rise along a normal to bring its segment's deepest
        point out of the body: its depth over the end's lever (:meth:`levers`) plus ``clearance`` (m).

        Returns
        -------
        ends : (J,) int64
            The free ends (a particle may appear once per crossing segment it ends).
        crossing : (J,) int64
            The crossing (of these rows) each belongs to.
        lift : (J,) float64
        """
        lever = self.levers(segments, is_root)
        moving = lever > 0.0
        crossing = np.broadcast_to(np.arange(self.count)[:, None], lever.shape)[moving]
        return segments[self.rows][moving], crossing, self.depth[crossing] / lever[moving] + clearance

    def through(self, points: np.ndarray, segments: np.ndarray, query: MeshQuery) -> np.ndarray:
        """``(K,) bool``: the crossing segments with an end whose own way out of the body opposes the one at
        their deepest point: through a thin part (a hand), where lifting the ends along a normal cannot
        clear them; the others sag into a curved skin from one side (their ends' normals and the deepest
        point's agree).

        Parameters
        ----------
        points : (N, 3) float64
        segments : (M, 2) int64
            The segments these rows index.
        query : MeshQuery
            The body.
        """
        ends = segments[self.rows].ravel()
        normal = query.signed_distance(points[ends]).normal.reshape(self.count, 2, 3)
        agreement = np.einsum("kej,kj->ke", normal, self.normal)
        return (agreement < 0.0).any(axis=1)

    def subset(self, keep: np.ndarray) -> "SegmentCrossings":
        """The crossings where ``keep (K,) bool``."""
        return SegmentCrossings(self.rows[keep], self.depth[keep], self.deepest_point[keep], self.deepest_at[keep],
                                self.normal[keep])

    def joined(self, other: "SegmentCrossings") -> "SegmentCrossings":
        """These crossings and ``other``'s (of other rows), rows ascending."""
        order = np.argsort(np.concatenate([self.rows, other.rows]), kind="stable")
        return SegmentCrossings(*(np.concatenate([mine, theirs])[order] for mine, theirs in (
            (self.rows, other.rows), (self.depth, other.depth), (self.deepest_point, other.deepest_point),
            (self.deepest_at, other.deepest_at), (self.normal, other.normal))))

    def report(self, segments: np.ndarray, offsets: np.ndarray) -> dict:
        """``{"count", "deepest_m", "deepest_strand", "deepest_segment"}`` for the metrics: the deepest crossing
        segment as its strand and its index along it (from the root); None when none crosses.

        Parameters
        ----------
        segments : (M, 2) int64
            The segments these rows index.
        offsets : (S + 1,) int64
            The strands' first particles.
        """
        if not self.count:
            return {"count": 0, "deepest_m": 0.0, "deepest_strand": None, "deepest_segment": None}
        worst = int(np.argmax(self.depth))
        first = int(segments[self.rows[worst], 0])
        strand = int(np.searchsorted(offsets, first, side="right") - 1)
        return {"count": self.count, "deepest_m": float(self.depth[worst]), "deepest_strand": strand,
                "deepest_segment": first - int(offsets[strand])}


def weld_runs(welded: np.ndarray) -> np.ndarray:
    """``(N,) int64``: the run of particles joined by degenerate segments each particle is in (``welded (N,) bool``:
    the particles that start one; a strand's tip starts none, so no run spans two strands)."""
    return np.cumsum(np.concatenate([[True], ~np.asarray(welded, dtype=bool)[:-1]])) - 1


def segment_entries(points: np.ndarray, segments: np.ndarray, is_root: np.ndarray,
                    query: MeshQuery) -> np.ndarray:
    """(M,) bool: segments whose interior meets the body's surface.

    Parameters
    ----------
    points : (N, 3) float64
    segments : (M, 2) int64
        Particle index pairs, root side first.
    is_root : (N,) bool
        A segment from a root is cast from its other end.
    query : MeshQuery
        The body (its collision surface).
    """
    first, second = segments[:, 0], segments[:, 1]
    from_root = np.asarray(is_root, dtype=bool)[first]
    origin = np.where(from_root[:, None], points[second], points[first])
    end = np.where(from_root[:, None], points[first], points[second])
    direction = end - origin
    length = np.linalg.norm(direction, axis=1)
    meets = np.zeros(len(segments), dtype=bool)
    cast = np.flatnonzero(length > 2.0 * END_TOLERANCE)
    if len(cast) == 0:
        return meets
    hits = query.first_hits(origin[cast], direction[cast])
    meets[cast] = hits.hit & (hits.distance > END_TOLERANCE) & (hits.distance < length[cast] - END_TOLERANCE)
    return meets


def crossing_segments(points: np.ndarray, segments: np.ndarray, is_root: np.ndarray, query: MeshQuery,
                      distance: np.ndarray | None = None, among: np.ndarray | None = None) -> SegmentCrossings:
    """The segments between two particles outside the body that pass through it, and how deep.

    Segments with an end inside the body are the particles' check's (:mod:`.penetration`), not counted here.

    Parameters
    ----------
    points : (N, 3) float64
    segments : (M, 2) int64
        Particle index pairs, root side first.
    is_root : (N,) bool
    query : MeshQuery
        The body (its collision surface: the sign of its distance is the inside test).
    distance : (N,) float64, optional
        Every particle's signed distance to the body (roots: anything), when the caller has it. Only
        segments shorter than the sum of their ends' distances can reach the body (every point of a
        segment is within half its length of an end), so only those are cast.
    among : (C,) int64, optional
        Rows of ``segments`` to check, ascending (all by default); the rest are not counted.
    """
    points = np.asarray(points, dtype=np.float64)
    segments = np.asarray(segments, dtype=np.int64).reshape(-1, 2)
    is_root = np.asarray(is_root, dtype=bool)
    if distance is None:
        # only the particles of these segments: a check of a few strands asks about their particles alone
        distance = np.zeros(len(points))
        ends = np.unique(segments)
        free = ends[~is_root[ends]]
        distance[free] = query.signed_distance(points[free]).distance if len(free) else 0.0
    distance = np.where(is_root, 0.0, distance)
    rows = np.arange(len(segments)) if among is None else np.asarray(among, dtype=np.int64)
    ends = segments[rows]
    ends_out = (distance[ends] >= 0.0).all(axis=1)
    length = np.linalg.norm(points[ends[:, 1]] - points[ends[:, 0]], axis=1)
    near = rows[ends_out & (distance[ends].sum(axis=1) < length)]
    candidates = near[segment_entries(points, segments[near], is_root, query)]
    return _depths(points, segments, candidates, query)


def _depths(points: np.ndarray, segments: np.ndarray, candidates: np.ndarray, query: MeshQuery) -> SegmentCrossings:
    """Sample the ``candidates`` segments (K,) along their length; keep those with a point inside."""
    k = len(candidates)
    at = np.arange(1, DEPTH_SAMPLES + 1) / (DEPTH_SAMPLES + 1)
    heads, tails = points[segments[candidates, 0]], points[segments[candidates, 1]]
    samples = heads[:, None, :] + at[None, :, None] * (tails - heads)[:, None, :]
    signed = query.signed_distance(samples.reshape(-1, 3))
    distance = signed.distance.reshape(k, DEPTH_SAMPLES)
    deepest = np.argmin(distance, axis=1) if k else np.zeros(0, dtype=np.int64)
    flat = np.arange(k) * DEPTH_SAMPLES + deepest
    depth = -distance[np.arange(k), deepest]
    # a ray's hit with no sample inside: the segment only grazes the surface (tangent, or deeper than
    # round-off between two samples, far below any clearance): still counted, at depth 0
    return SegmentCrossings(rows=candidates, depth=np.maximum(depth, 0.0), deepest_point=samples.reshape(-1, 3)[flat],
                            deepest_at=at[deepest], normal=signed.normal[flat])
