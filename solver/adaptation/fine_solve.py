"""The outer loop of :func:`.active_set.solve_strands` for uncoupled strands, on compiled kernels.

When ``K`` is diagonal (Eq. 14's fine level) every strand is its own problem with its own
line search, damping, merit penalty and convergence test. This loop does what the numpy
reference in :mod:`.active_set` does, iteration for iteration, but never copies the problem:
the kernels of :mod:`.strand_kernels` and :mod:`.line_search_kernels` take the chunk's
arrays and the list of open strands, each strand's QP runs in one compiled pass over its own
particles (strands in parallel on numba's threads), and only the particles of strands still
backtracking are packed for the batched distance query of each line-search attempt, which
asks only about the trial points whose distance bound from their particle's last query is
short of ``eps_c`` plus :data:`.options.QUERY_MARGIN` (:class:`.constraints.QueryAnchors`).

Working memory beyond the problem's arrays: the iterate, its distance, normal and flags, the
step, the last queries' anchors (about 170 bytes per particle), the packed trial points of one attempt (about 60) and
the distance query's temporaries (about 280 on a whole-chunk batch, measured at 10^5).

Convention: particles ``(N, 3) float64`` in meters, strands in CSR layout (``offsets``).
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np
import scipy.sparse as sp

from hairport.solver.adaptation import line_search_kernels, strand_kernels
from hairport.solver.adaptation.constraints import BodyDistance, push_out_short
from hairport.solver.adaptation.energies import NEGATIVE_CURVATURE_SHARE, PARALLEL_SINE, WELD_LENGTH_M, EnergyWeights
from hairport.solver.adaptation.options import (
    BACKTRACK_FACTOR,
    INITIAL_RADIAL_DAMPING,
    MAX_ACTIVE_SET_ROUNDS,
    MAX_BACKTRACKS,
    MERIT_PENALTY_FACTOR,
    Cancelled,
    SolveOptions,
    SolveReport,
    adapt_damping,
    groups_done,
)
from hairport.solver.adaptation.strand_problem import StrandProblem
from hairport.solver.jit import set_threads, threads
from hairport.solver.mesh.polyline import MIN_SEGMENT_LENGTH
from hairport.solver.model.progress import ProgressFn

#: open strands with fewer particles than this are stepped on one thread: their QPs take less
#: time (~2 us a particle) than a parallel region can cost on a busy machine (its barrier waits
#: for a descheduled thread)
PARALLEL_MIN_PARTICLES = 5_000


def pull_weights(coupling: sp.csr_matrix) -> np.ndarray | None:
    """The diagonal ``(N,)`` of ``K`` when it has no other entry (each particle pulled on its own), else None."""
    K = coupling.tocoo()
    if np.any(K.data[K.row != K.col] != 0.0):
        return None
    return np.ascontiguousarray(coupling.diagonal(), dtype=np.float64)


def _packed_offsets(offsets: np.ndarray, strands: np.ndarray) -> np.ndarray:
    """``(T+1,) int64``: where each listed strand's rows start when they are packed back to back."""
    packed = np.zeros(len(strands) + 1, dtype=np.int64)
    np.cumsum(offsets[strands + 1] - offsets[strands], out=packed[1:])
    return packed


def strand_rows(offsets: np.ndarray, strands: np.ndarray) -> np.ndarray:
    """``(P,) int64``: the particles of the listed strands ``(T,) int64``, strand after strand."""
    packed = _packed_offsets(offsets, strands)
    return np.arange(packed[-1], dtype=np.int64) + np.repeat(offsets[strands] - packed[:-1], np.diff(packed))


def solve_uncoupled(
    problem: StrandProblem,
    distance: BodyDistance,
    weights: EnergyWeights = EnergyWeights(),
    options: SolveOptions = SolveOptions(),
    start: np.ndarray | None = None,
    progress: ProgressFn | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> tuple[np.ndarray, SolveReport]:
    """Minimise Eq. 1 under Eq. 12-13 over independent strands (``K`` diagonal), on compiled kernels.

    The same loop as :func:`.active_set.solve_strands` on an uncoupled problem (its numpy
    code is the reference this one is tested against).

    Parameters
    ----------
    problem : StrandProblem
        With a diagonal ``coupling`` (:func:`pull_weights`).
    distance : BodyDistance
    weights : EnergyWeights
    options : SolveOptions
    start : (N, 3) float64, optional
        First iterate (``problem.initial`` by default).
    progress : ProgressFn, optional
        ``progress("solve", fraction, message)`` after every outer iteration.
    should_stop : callable() -> bool, optional
        Polled once per outer iteration; True raises :class:`.options.Cancelled`.

    Returns
    -------
    points : (N, 3) float64
    report : SolveReport
        ``backend`` left empty for the caller to name.

    Raises
    ------
    ValueError
        If ``K`` links two particles.
    numpy.linalg.LinAlgError
        If a strand's Newton system is not positive definite.
    """
    began = time.perf_counter()
    pull_weight = pull_weights(problem.coupling)
    if pull_weight is None:
        raise ValueError("the compiled loop needs a diagonal K (independent particles' pulls)")
    offsets = np.ascontiguousarray(problem.offsets, dtype=np.int64)
    arrays = dict(
        source_directions=np.ascontiguousarray(problem.source_directions, dtype=np.float64),
        initial=np.ascontiguousarray(problem.initial, dtype=np.float64),
        pull_weight=pull_weight,
        features=np.ascontiguousarray(problem.features, dtype=np.float64),
        gamma=np.ascontiguousarray(problem.gamma, dtype=np.float64),
        # without the term the kernels read no rest length: one stub instead of N zeros
        rest_lengths=np.ascontiguousarray(problem.spacing_rest(weights) if weights.spacing else np.zeros(1),
                                          dtype=np.float64),
        fixed=np.ascontiguousarray(problem.fixed, dtype=np.bool_),
    )
    fixed = arrays["fixed"]
    # the merit kernels' problem arguments, in their order
    problem_arrays = (arrays["source_directions"], arrays["initial"], pull_weight, arrays["features"], arrays["gamma"],
                      arrays["rest_lengths"])
    alpha, beta, eps_c = float(weights.alpha), float(weights.beta), float(options.eps_c)
    spacing = (float(weights.spacing), float(weights.spacing_band[0]), float(weights.spacing_band[1]))
    n_strands = problem.n_strands
    points = np.array(problem.initial if start is None else start, dtype=np.float64, order="C")
    report = SolveReport(groups=n_strands)

    damping = np.full(n_strands, INITIAL_RADIAL_DAMPING)
    penalty = np.zeros(n_strands)  # each strand's own: a strand's result does not depend on its chunk
    small_steps = np.zeros(n_strands, dtype=np.int64)  # consecutive iterations below the energy tolerance
    active = np.zeros(problem.n_particles, dtype=bool)
    step = np.zeros_like(points)
    dist, normal, near = distance(points)
    dist, normal, near = (np.ascontiguousarray(dist, dtype=np.float64), np.ascontiguousarray(normal, dtype=np.float64),
                          np.ascontiguousarray(near, dtype=np.bool_))
    anchor_points, anchor_distance, anchor_normal, anchor_near = points.copy(), dist.copy(), normal.copy(), near.copy()
    bounded = np.zeros(problem.n_particles, dtype=bool)  # the iterate's distance is a bound (QueryAnchors)
    least = eps_c + float(options.query_margin)
    open_strands = np.arange(n_strands, dtype=np.int64)
    all_threads = threads()
    for iteration in range(options.max_iterations):
        if len(open_strands) == 0:
            break
        if should_stop is not None and should_stop():
            raise Cancelled("solve cancelled")
        k = len(open_strands)
        rounds = np.zeros(k, dtype=np.int64)
        predicted, merit_now = np.zeros(k), np.zeros(k)
        open_particles = int(np.sum(offsets[open_strands + 1] - offsets[open_strands]))
        set_threads(all_threads if open_particles >= PARALLEL_MIN_PARTICLES else 1)
        active_before, penalty_before = active.copy(), penalty.copy()
        qp_strands, qp_rounds, qp_predicted = open_strands, rounds, predicted
        hit = np.zeros(len(open_strands), dtype=bool)
        try:
            while True:
                strand_kernels.newton_qp_steps(
                    qp_strands, offsets, points, dist, normal, near, arrays["source_directions"], arrays["initial"],
                    pull_weight, arrays["features"], arrays["gamma"], arrays["rest_lengths"], fixed, alpha, beta, *spacing,
                    eps_c, damping, penalty,
                    active, step, qp_rounds, qp_predicted, MIN_SEGMENT_LENGTH, WELD_LENGTH_M, NEGATIVE_CURVATURE_SHARE,
                    PARALLEL_SINE, MERIT_PENALTY_FACTOR, MAX_ACTIVE_SET_ROUNDS,
                )
                if qp_strands is not open_strands:
                    rounds[hit], predicted[hit] = qp_rounds, qp_predicted
                hit = np.zeros(len(open_strands), dtype=bool)  # a new array: the old one indexed the solve above
                line_search_kernels.reaching_strands(open_strands, offsets, step, dist, bounded, eps_c, hit)
                if not hit.any():
                    break
                # a step reaches a bounded particle's slack: that strand's bounded particles are
                # queried and its QP solved again from the same state (see QueryAnchors)
                qp_strands = open_strands[hit]
                rows = strand_rows(offsets, qp_strands)
                again = rows[bounded[rows]]
                dist[again], normal[again], near[again] = distance(points[again])
                anchor_points[again], anchor_distance[again] = points[again], dist[again]
                anchor_normal[again], anchor_near[again], bounded[again] = normal[again], near[again], False
                active[rows], penalty[qp_strands] = active_before[rows], penalty_before[qp_strands]
                qp_rounds, qp_predicted = np.zeros(len(qp_strands), dtype=np.int64), np.zeros(len(qp_strands))
        finally:
            set_threads(all_threads)
        line_search_kernels.strand_merits(open_strands, offsets, offsets[open_strands], points, dist, *problem_arrays,
                                          fixed, alpha, beta, *spacing, penalty, eps_c, MIN_SEGMENT_LENGTH, WELD_LENGTH_M, merit_now)
        if np.any(rounds < 0):
            raise np.linalg.LinAlgError("a strand's Newton system is not positive definite")
        report.active_set_rounds.append(int(rounds.max()))
        report.cg_steps.append(int(rounds.max()))  # one banded solve per round, no CG
        report.open_groups.append(k)

        fraction = np.ones(k)
        accepted = np.zeros(k, dtype=bool)
        merit_trial = np.zeros(k)
        max_step, shortfall, min_clearance = np.zeros(k), np.zeros(k), np.zeros(k)
        for attempt in range(MAX_BACKTRACKS):
            todo = np.flatnonzero(~accepted)
            strands = open_strands[todo]
            packed = _packed_offsets(offsets, strands)
            moved = np.empty((packed[-1], 3))
            free = np.empty(packed[-1], dtype=bool)
            line_search_kernels.gather_trial_points(strands, offsets, packed, points, step, fraction[todo], fixed,
                                                    moved, free)
            d, nrm = np.empty(len(moved)), np.empty((len(moved), 3))
            nr, queried = np.empty(len(moved), dtype=bool), np.empty(len(moved), dtype=bool)
            line_search_kernels.bound_trial_distances(strands, offsets, packed, moved, anchor_points, anchor_distance,
                                                      anchor_normal, anchor_near, least, d, nrm, nr, queried)
            if queried.any():
                d[queried], nrm[queried], nr[queried] = distance(moved[queried])
            short = nr & (d < eps_c) & free
            if short.any():
                # second-order correction: the linearised half-spaces ignore the body's curvature
                moved[short] += (eps_c - d[short])[:, None] * nrm[short]
                d[short], nrm[short], nr[short] = distance(moved[short])
            todo_merit = np.zeros(len(todo))
            line_search_kernels.strand_merits(strands, offsets, packed[:-1], moved, d, *problem_arrays, fixed, alpha,
                                              beta, *spacing, penalty, eps_c, MIN_SEGMENT_LENGTH, WELD_LENGTH_M, todo_merit)
            merit_trial[todo] = todo_merit
            if attempt == 0:
                damping[open_strands] = adapt_damping(damping[open_strands], merit_trial - merit_now, predicted)
            now_accepted = todo_merit <= merit_now[todo]
            todo_step, todo_short, todo_clearance = np.zeros(len(todo)), np.zeros(len(todo)), np.zeros(len(todo))
            line_search_kernels.commit_trial_points(
                strands, offsets, packed, now_accepted, moved, d, nrm, nr, fixed, eps_c, points, dist, normal, near,
                todo_step, todo_short, todo_clearance,
            )
            line_search_kernels.commit_anchors(strands, offsets, packed, now_accepted, queried, moved, d, nrm, nr,
                                               anchor_points, anchor_distance, anchor_normal, anchor_near, bounded)
            max_step[todo] = todo_step
            shortfall[todo] = todo_short
            min_clearance[todo] = todo_clearance
            accepted[todo] = now_accepted
            if accepted.all() or attempt == MAX_BACKTRACKS - 1:
                break
            fraction = np.where(accepted, fraction, BACKTRACK_FACTOR * fraction)
        # a strand whose every trial raised the merit stays where it is (see solve_strands)
        failed = ~accepted
        if failed.any():
            stuck = open_strands[failed]
            stuck_short, stuck_clearance = np.zeros(len(stuck)), np.zeros(len(stuck))
            line_search_kernels.strand_clearances(stuck, offsets, dist, fixed, eps_c, stuck_short, stuck_clearance)
            shortfall[failed], min_clearance[failed] = stuck_short, stuck_clearance
            max_step[failed], fraction[failed], merit_trial[failed] = 0.0, 0.0, merit_now[failed]
        done, small_steps[open_strands] = groups_done(
            options, merit_now, merit_trial, failed, small_steps[open_strands], max_step, shortfall, predicted)
        open_strands = open_strands[~done]
        report.end_iteration(iteration, merit_trial, fraction, done, max_step, min_clearance.min(initial=np.inf),
                             len(open_strands), options.max_iterations, progress)
    report.converged = len(open_strands) == 0
    if not report.converged:
        points, report.pushed_out = push_out_short(
            points, fixed, dist, distance.query, options.eps_c, options.clearance_tolerance
        )
    report.seconds = time.perf_counter() - began
    return points, report
