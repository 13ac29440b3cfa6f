"""Whole strands outside the body: segments that dip into it between two particles held outside.

Eq. 13 keeps every particle ``eps_c`` out, but a renderer draws the straight segments between them,
and a chord of length ``L`` over a surface of radius ``R`` sags ``L^2 / 8R`` into it (0.6 mm for
16 mm segments over a 5 cm shoulder). After a solve, :func:`clear_segments` finds the segments
that pass through the body (exactly: :mod:`hairport.solver.mesh.segment_crossing`) and solves
again a stretch of strand around each (:func:`segment_windows`, :func:`window_problem`: the rest
held where it is), from where it is, with a clearance of their own for the ends of such segments
(:meth:`~.problem.constraints.BodyDistance.with_margin`): enough to lift each segment's deepest
point to ``eps_c`` (:func:`lift_margins`). Rounds repeat, margins only growing, until no segment
crosses or :attr:`~.loop.options.SolveOptions.segment_rounds` (:data:`~.loop.options.SEGMENT_ROUNDS`).

Why margins on particles rather than constraints on points along segments: the per-particle
QP (:mod:`.fine.strand_kernels`) pins one rotated coordinate per active particle, which a
two-particle row does not fit; a margin keeps that structure, and it is placed only on the ends of
the segments that cross, so the rest of the hair keeps the paper's clearance.

Convention: particles ``(N, 3) float64`` in meters, strands in CSR layout (``offsets``).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from hairport.solver.adaptation.loop.options import SolveOptions, SolveReport
from hairport.solver.adaptation.problem.constraints import BodyDistance
from hairport.solver.adaptation.problem.strand_problem import StrandProblem
from hairport.solver.mesh.segment_crossing import SegmentCrossings, crossing_segments, weld_runs

#: particles on either side of a crossing segment solved again with it (the rest of its strand held): a
#: lift of a segment's ends spreads along the strand over a few segments, and a whole 100-particle strand
#: solved again for one segment cost 8 times the work
WINDOW_REACH = 4
#: the largest clearance (m) a margin asks of one particle: a segment that needs more is not a
#: sag over a curved surface but a strand through a thin part, which lifting its ends cannot fix
MAX_MARGIN = 0.01

#: solves a problem from a start under a distance with margins: ``(problem, distance, start) -> (points, report)``
SolveFn = Callable[[StrandProblem, BodyDistance, np.ndarray], "tuple[np.ndarray, SolveReport]"]


def problem_segments(problem: StrandProblem) -> np.ndarray:
    """``(M, 2) int64``: every segment of the problem's strands, root side first."""
    starts = problem.segment_starts
    return np.stack([starts, starts + 1], axis=1)


def lift_margins(segments: np.ndarray, fixed: np.ndarray, crossings: SegmentCrossings, distance: np.ndarray,
                 eps_c: float, margin: np.ndarray) -> np.ndarray:
    """The margins that lift each crossing segment's deepest point to ``eps_c`` outside.

    Each free end of a crossing segment is asked to rise by the deepest point's depth over its lever
    (:meth:`~hairport.solver.mesh.segment_crossing.SegmentCrossings.levers`: 1 when both ends move; the
    free end's share of the segment next to a root), plus ``eps_c``: the deepest point then sits
    ``eps_c`` out, or, next to a root (on the surface), its share of it.

    Parameters
    ----------
    segments : (M, 2) int64
    fixed : (N,) bool
    crossings : SegmentCrossings
        Over ``segments``.
    distance : (N,) float64
        Each particle's signed distance to the body (m; read at the ends of crossing segments).
    eps_c : float
    margin : (N,) float64
        The margins so far (m).

    Returns
    -------
    margin : (N,) float64
        A new array, at least ``margin`` everywhere, new ones at most :data:`MAX_MARGIN`.
    """
    ends, _, lift = crossings.end_lifts(segments, fixed, eps_c)
    wanted = np.array(margin, dtype=np.float64)
    np.maximum.at(wanted, ends, np.minimum(distance[ends] + lift - eps_c, MAX_MARGIN))
    return wanted


def welded_run_ids(problem: StrandProblem) -> np.ndarray:
    """``(N,) int64``: the run of particles joined by welded segments (a zero source direction) each one is in."""
    starts_weld = ~np.any(problem.source_directions != 0.0, axis=1)
    starts_weld[problem.offsets[1:] - 1] = False  # a tip starts no segment
    return weld_runs(starts_weld)


def welded_maximum(margin: np.ndarray, runs: np.ndarray) -> np.ndarray:
    """Each particle's margin raised to the largest of its welded run (``runs``: :func:`welded_run_ids`), so that a
    weld's particles keep one clearance and stay together."""
    if len(margin) == 0:
        return margin
    largest = np.zeros(runs[-1] + 1)
    np.maximum.at(largest, runs, margin)
    return largest[runs]


def segment_windows(offsets: np.ndarray, rows: np.ndarray, reach: int) -> np.ndarray:
    """The stretches of strands around some segments: ``(W, 2) int64`` particle ranges ``[first, stop)``.

    Each segment starting at particle ``rows (K,) int64`` gets the ``reach`` particles on either side of
    it, within its strand; stretches of one strand that overlap or touch are merged, ascending.
    """
    strand = np.searchsorted(offsets, rows, side="right") - 1
    first = np.maximum(rows - reach, offsets[strand])
    stop = np.minimum(rows + 2 + reach, offsets[strand + 1])
    order = np.lexsort((first, strand))
    strand, first, stop = strand[order], first[order], stop[order]
    # a stretch starts a new window unless it meets the previous one of its strand
    reach_so_far = np.maximum.accumulate(stop)
    new = np.ones(len(first), dtype=bool)
    new[1:] = (strand[1:] != strand[:-1]) | (first[1:] > reach_so_far[:-1])
    starts = np.flatnonzero(new)
    ends = np.maximum.reduceat(stop, starts) if len(starts) else np.zeros(0, dtype=np.int64)
    return np.stack([first[starts], ends], axis=1).astype(np.int64)


def window_problem(problem: StrandProblem, windows: np.ndarray, points: np.ndarray) -> tuple[StrandProblem, np.ndarray]:
    """The problem over stretches of its strands, everything else held at ``points (N, 3)``.

    Each window ``[first, stop)`` (:func:`segment_windows`) becomes a strand of its own whose end particles
    are fixed unless they are its strand's own ends (a root is fixed anyway; a tip stays free): Eq. 1's
    terms are per segment and per particle, so its energy is the whole problem's as a function of the
    window's free particles, up to a constant. ``K`` becomes diagonal, each row keeping the held
    particles' share in the features (one block-Jacobi step where strands are coupled), so the
    compiled level solves the windows.

    Parameters
    ----------
    problem : StrandProblem
    windows : (W, 2) int64
    points : (N, 3) float64
        Where everything outside the windows is held.

    Returns
    -------
    problem : StrandProblem
        With a diagonal ``coupling``, one strand per window.
    index : (n,) int64
        Its particles in ``problem``.
    """
    counts = windows[:, 1] - windows[:, 0]
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    index = np.repeat(windows[:, 0] - offsets[:-1], counts) + np.arange(offsets[-1])
    fixed = problem.fixed[index].copy()
    strand_starts = np.zeros(problem.n_particles + 1, dtype=bool)
    strand_starts[problem.offsets] = True
    cut_before = ~strand_starts[windows[:, 0]]
    cut_after = ~strand_starts[windows[:, 1]]
    fixed[offsets[:-1][cut_before]] = True
    fixed[offsets[1:][cut_after] - 1] = True
    coupling = problem.coupling.tocsr()
    diagonal = coupling.diagonal()
    others = coupling[index] @ points - diagonal[index, None] * points[index]
    sub = StrandProblem(
        offsets, problem.source_directions[index], problem.initial[index],
        sp.diags(diagonal[index], format="csr"), problem.features[index] - others, problem.gamma[index], fixed,
        None if problem.rest_lengths is None else problem.rest_lengths[index],
    )
    return sub, index


def clear_segments(problem: StrandProblem, distance: BodyDistance, options: SolveOptions, points: np.ndarray,
                   report: SolveReport, solve: SolveFn, particle_distance: np.ndarray | None = None) -> np.ndarray:
    """Solve again, with margins, the strands that have a segment through the body, until none has.

    Parameters
    ----------
    problem : StrandProblem
    distance : BodyDistance
        The solve's (no margins).
    options : SolveOptions
        ``eps_c`` and ``segment_rounds`` (0: no check).
    points : (N, 3) float64
        The solve's result.
    report : SolveReport
        Receives ``segments_crossing`` (found after the solve), ``segment_rounds``, ``segments_left`` and
        ``segment_seconds``.
    solve : SolveFn
        Runs the solve's loop over a subset of the strands.
    particle_distance : (N,) float64, optional
        The solve's last distances of ``points`` (a lower bound or ``inf`` far from the body are fine:
        they only spare segments a ray).

    Returns
    -------
    points : (N, 3) float64
        ``points`` itself when no segment crossed, else a new array.
    """
    if options.segment_rounds <= 0 or problem.n_particles == 0:
        return points
    began = time.perf_counter()
    segments = problem_segments(problem)
    welded_runs = welded_run_ids(problem)
    query = distance.query
    margin = np.zeros(problem.n_particles)
    checked = np.arange(len(segments))
    for round_number in range(options.segment_rounds + 1):
        found = crossing_segments(points, segments[checked], problem.fixed, query,
                                  particle_distance if round_number == 0 else None)
        crossings = dataclasses.replace(found, rows=checked[found.rows])
        if round_number == 0:
            report.segments_crossing = crossings.count
        report.segments_left = crossings.count
        if crossings.count == 0 or round_number == options.segment_rounds:
            break
        ends = np.unique(segments[crossings.rows].ravel())
        end_distance = np.zeros(problem.n_particles)
        end_distance[ends] = query.signed_distance(points[ends]).distance
        margin = welded_maximum(lift_margins(segments, problem.fixed, crossings, end_distance, options.eps_c, margin),
                                welded_runs)
        windows = segment_windows(problem.offsets, segments[crossings.rows, 0], WINDOW_REACH)
        sub, index = window_problem(problem, windows, points)
        solved, _ = solve(sub, distance.with_margin(margin[index]), points[index])
        points = np.array(points, dtype=np.float64)
        points[index] = solved
        report.segment_rounds = round_number + 1
        # only the segments of the windows solved again can have changed
        moved = np.zeros(problem.n_particles + 1, dtype=bool)
        moved[index] = True
        checked = np.flatnonzero(moved[segments[:, 0]] | moved[segments[:, 1]])
    report.segment_seconds = time.perf_counter() - began
    return points
