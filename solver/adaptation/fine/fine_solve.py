"""The fine level of the active-set loop (:mod:`~hairport.solver.adaptation.loop.active_set`) on compiled kernels.

When ``K`` is diagonal (Eq. 14's fine level) every strand is its own problem with its own line
search, damping, merit penalty and convergence test. :class:`CompiledLevel` does what the numpy
level (:class:`~hairport.solver.adaptation.coupled.numpy_level.NumpyLevel`, its tested reference)
does, iteration for iteration, but never copies the problem: the kernels of :mod:`.strand_kernels`
and :mod:`.line_search_kernels` take the chunk's arrays and the list of open strands, each
strand's QP runs in one compiled pass over its own particles (strands in parallel on numba's
threads), and only the particles of strands still backtracking are packed for the batched distance
query of each line-search attempt, which asks only about the trial points whose distance bound
from their particle's last query is short of ``eps_c`` plus
:data:`~hairport.solver.adaptation.loop.options.QUERY_MARGIN`
(:class:`~hairport.solver.adaptation.problem.constraints.QueryAnchors`).

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

from hairport.solver.adaptation.fine import line_search_kernels, strand_kernels
from hairport.solver.adaptation.loop.active_set import NewtonStep, StepOutcome, run_active_set
from hairport.solver.adaptation.loop.options import (
    MAX_ACTIVE_SET_ROUNDS,
    MERIT_PENALTY_FACTOR,
    SolveOptions,
    SolveReport,
)
from hairport.solver.adaptation.problem import merit_kernels
from hairport.solver.adaptation.problem.constraints import BodyDistance
from hairport.solver.adaptation.problem.energies import (
    NEGATIVE_CURVATURE_SHARE,
    PARALLEL_SINE,
    WELD_LENGTH_M,
    EnergyWeights,
)
from hairport.solver.adaptation.problem.strand_problem import StrandProblem
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
    """Minimise Eq. 1 under Eq. 12-13 over independent strands (``K`` diagonal): the active-set loop
    (:func:`~hairport.solver.adaptation.loop.active_set.run_active_set`) over a :class:`CompiledLevel`.

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
        Polled once per outer iteration; True raises :class:`~hairport.solver.adaptation.loop.options.Cancelled`.

    Returns
    -------
    points : (N, 3) float64
    report : SolveReport

    Raises
    ------
    ValueError
        If ``K`` links two particles.
    numpy.linalg.LinAlgError
        If a strand's Newton system is not positive definite.
    """
    began = time.perf_counter()
    level = CompiledLevel(problem, distance, weights, options, start)
    return run_active_set(level, options, progress, should_stop, began)


class CompiledLevel:
    """One uncoupled solve's iterate and per-iteration state, on the compiled kernels; stepped by
    :func:`~hairport.solver.adaptation.loop.active_set.run_active_set` (see
    :class:`~hairport.solver.adaptation.loop.active_set.ActiveSetLevel` for the methods). Every strand
    is a group.

    Parameters
    ----------
    problem : StrandProblem
        With a diagonal ``coupling`` (:func:`pull_weights`).
    body : BodyDistance
    weights : EnergyWeights
    options : SolveOptions
    start : (N, 3) float64, optional
        First iterate (``problem.initial`` by default).

    Raises
    ------
    ValueError
        If ``K`` links two particles.
    """

    coupled = False

    def __init__(self, problem: StrandProblem, body: BodyDistance, weights: EnergyWeights, options: SolveOptions,
                 start: np.ndarray | None = None):
        pull_weight = pull_weights(problem.coupling)
        if pull_weight is None:
            raise ValueError("the compiled loop needs a diagonal K (independent particles' pulls)")
        self.body = body
        self.offsets = np.ascontiguousarray(problem.offsets, dtype=np.int64)
        # the merit kernels' problem arguments, in their order
        self.problem_arrays = (
            np.ascontiguousarray(problem.source_directions, dtype=np.float64),
            np.ascontiguousarray(problem.initial, dtype=np.float64),
            pull_weight,
            np.ascontiguousarray(problem.features, dtype=np.float64),
            np.ascontiguousarray(problem.gamma, dtype=np.float64),
            # without the term the kernels read no rest length: one stub instead of N zeros
            np.ascontiguousarray(problem.spacing_rest(weights) if weights.spacing else np.zeros(1), dtype=np.float64),
        )
        self.fixed = np.ascontiguousarray(problem.fixed, dtype=np.bool_)
        self.alpha, self.beta, self.eps_c = float(weights.alpha), float(weights.beta), float(options.eps_c)
        self.spacing = (float(weights.spacing), float(weights.spacing_band[0]), float(weights.spacing_band[1]))
        self.n_strands = self.n_groups = problem.n_strands
        self.points = np.array(problem.initial if start is None else start, dtype=np.float64, order="C")
        self.penalty = np.zeros(self.n_strands)  # each strand's own: a strand's result does not depend on its chunk
        self.active = np.zeros(problem.n_particles, dtype=bool)
        self.step = np.zeros_like(self.points)
        dist, normal, near = body(self.points)
        self.distance, self.normal, self.near = (
            np.ascontiguousarray(dist, dtype=np.float64), np.ascontiguousarray(normal, dtype=np.float64),
            np.ascontiguousarray(near, dtype=np.bool_))
        self.anchors = (self.points.copy(), self.distance.copy(), self.normal.copy(), self.near.copy())
        self.bounded = np.zeros(problem.n_particles, dtype=bool)  # the iterate's distance is a bound (QueryAnchors)
        self.least = self.eps_c + float(options.query_margin)
        self.all_threads = threads()

    def newton_step(self, open_strands: np.ndarray, damping: np.ndarray) -> NewtonStep:
        k = len(open_strands)
        rounds, predicted = self._contact_qps(open_strands, damping)
        merit_now = np.zeros(k)
        self._merits(open_strands, self.offsets[open_strands], self.points, self.distance, merit_now)
        if np.any(rounds < 0):
            raise np.linalg.LinAlgError("a strand's Newton system is not positive definite")
        self.open_strands, self.merit_now = open_strands, merit_now
        self.merit_trial = np.zeros(k)
        self.max_step, self.shortfall, self.min_clearance = np.zeros(k), np.zeros(k), np.zeros(k)
        # one banded solve per round, no CG
        return NewtonStep(open_strands, merit_now, merit_now, predicted, int(rounds.max()), int(rounds.max()))

    def _contact_qps(self, open_strands: np.ndarray, damping: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Each open strand's QP (:func:`.strand_kernels.newton_qp_steps`): its rounds ``(k,) int64`` (-1: not
        positive definite) and predicted merit change ``(k,)``; the steps into ``self.step``.

        A step that reaches a bounded particle's slack has that strand's bounded particles queried
        and its QP solved again from the same state (see QueryAnchors)."""
        offsets, points, dist, normal, near, bounded = (self.offsets, self.points, self.distance, self.normal,
                                                        self.near, self.bounded)
        anchor_points, anchor_distance, anchor_normal, anchor_near = self.anchors
        rounds = np.zeros(len(open_strands), dtype=np.int64)
        predicted = np.zeros(len(open_strands))
        open_particles = int(np.sum(offsets[open_strands + 1] - offsets[open_strands]))
        set_threads(self.all_threads if open_particles >= PARALLEL_MIN_PARTICLES else 1)
        active_before, penalty_before = self.active.copy(), self.penalty.copy()
        qp_strands, qp_rounds, qp_predicted = open_strands, rounds, predicted
        hit = np.zeros(len(open_strands), dtype=bool)
        try:
            while True:
                strand_kernels.newton_qp_steps(
                    qp_strands, offsets, points, dist, normal, near, *self.problem_arrays, self.fixed, self.alpha,
                    self.beta, *self.spacing, self.eps_c, damping, self.penalty, self.active, self.step, qp_rounds,
                    qp_predicted, MIN_SEGMENT_LENGTH, WELD_LENGTH_M, NEGATIVE_CURVATURE_SHARE, PARALLEL_SINE,
                    MERIT_PENALTY_FACTOR, MAX_ACTIVE_SET_ROUNDS,
                )
                if qp_strands is not open_strands:
                    rounds[hit], predicted[hit] = qp_rounds, qp_predicted
                hit = np.zeros(len(open_strands), dtype=bool)  # a new array: the old one indexed the solve above
                line_search_kernels.reaching_strands(open_strands, offsets, self.step, dist, bounded, self.eps_c, hit)
                if not hit.any():
                    break
                qp_strands = open_strands[hit]
                rows = strand_rows(offsets, qp_strands)
                again = rows[bounded[rows]]
                dist[again], normal[again], near[again] = self.body(points[again], again)
                anchor_points[again], anchor_distance[again] = points[again], dist[again]
                anchor_normal[again], anchor_near[again], bounded[again] = normal[again], near[again], False
                self.active[rows], self.penalty[qp_strands] = active_before[rows], penalty_before[qp_strands]
                qp_rounds, qp_predicted = np.zeros(len(qp_strands), dtype=np.int64), np.zeros(len(qp_strands))
        finally:
            set_threads(self.all_threads)
        return rounds, predicted

    def _merits(self, strands: np.ndarray, first_rows: np.ndarray, positions: np.ndarray, distance: np.ndarray,
                out: np.ndarray) -> None:
        """:func:`.merit_kernels.strand_merits` of ``strands`` whose rows start at ``first_rows`` of
        ``positions`` and ``distance``, into ``out``."""
        merit_kernels.strand_merits(strands, self.offsets, first_rows, positions, distance, *self.problem_arrays,
                                    self.fixed, self.alpha, self.beta, *self.spacing, self.penalty, self.eps_c,
                                    MIN_SEGMENT_LENGTH, WELD_LENGTH_M, out)

    def trial_merits(self, fraction: np.ndarray, accepted: np.ndarray) -> np.ndarray:
        eps_c, offsets = self.eps_c, self.offsets
        todo = np.flatnonzero(~accepted)
        strands = self.open_strands[todo]
        packed = _packed_offsets(offsets, strands)
        moved = np.empty((packed[-1], 3))
        free = np.empty(packed[-1], dtype=bool)
        line_search_kernels.gather_trial_points(strands, offsets, packed, self.points, self.step, fraction[todo],
                                                self.fixed, moved, free)
        d, nrm = np.empty(len(moved)), np.empty((len(moved), 3))
        nr, queried = np.empty(len(moved), dtype=bool), np.empty(len(moved), dtype=bool)
        line_search_kernels.bound_trial_distances(strands, offsets, packed, moved, *self.anchors, self.least, d, nrm,
                                                  nr, queried)
        # the particles of the packed rows, for a body with margins (BodyDistance.with_margin)
        rows = None if self.body.margin is None else strand_rows(offsets, strands)
        if queried.any():
            d[queried], nrm[queried], nr[queried] = self.body(moved[queried], None if rows is None else rows[queried])
        short = nr & (d < eps_c) & free
        if short.any():
            # second-order correction: the linearised half-spaces ignore the body's curvature
            moved[short] += (eps_c - d[short])[:, None] * nrm[short]
            d[short], nrm[short], nr[short] = self.body(moved[short], None if rows is None else rows[short])
        todo_merit = np.zeros(len(todo))
        self._merits(strands, packed[:-1], moved, d, todo_merit)
        self.merit_trial[todo] = todo_merit
        self.trial = (todo, strands, packed, moved, d, nrm, nr, queried)
        return self.merit_trial

    def keep(self, accepted: np.ndarray) -> None:
        """The strands just accepted move to their trial points (with their anchors)."""
        todo, strands, packed, moved, d, nrm, nr, queried = self.trial
        now_accepted = accepted[todo]
        todo_step, todo_short, todo_clearance = np.zeros(len(todo)), np.zeros(len(todo)), np.zeros(len(todo))
        line_search_kernels.commit_trial_points(
            strands, self.offsets, packed, now_accepted, moved, d, nrm, nr, self.fixed, self.eps_c, self.points,
            self.distance, self.normal, self.near, todo_step, todo_short, todo_clearance,
        )
        line_search_kernels.commit_anchors(strands, self.offsets, packed, now_accepted, queried, moved, d, nrm, nr,
                                           *self.anchors, self.bounded)
        self.max_step[todo] = todo_step
        self.shortfall[todo] = todo_short
        self.min_clearance[todo] = todo_clearance

    def settle(self, stays: np.ndarray) -> StepOutcome:
        failed = stays
        max_step, shortfall, min_clearance, merit_trial = self.max_step, self.shortfall, self.min_clearance, \
            self.merit_trial
        if failed.any():
            stuck = self.open_strands[failed]
            stuck_short, stuck_clearance = np.zeros(len(stuck)), np.zeros(len(stuck))
            line_search_kernels.strand_clearances(stuck, self.offsets, self.distance, self.fixed, self.eps_c,
                                                  stuck_short, stuck_clearance)
            shortfall[failed], min_clearance[failed] = stuck_short, stuck_clearance
            max_step[failed], merit_trial[failed] = 0.0, self.merit_now[failed]
        return StepOutcome(merit_trial, failed, max_step, shortfall, min_clearance.min(initial=np.inf))
