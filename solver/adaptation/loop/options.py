"""What both QP backends share: solve options, cancellation, the single-level solve report,
the merit penalty and the Levenberg-Marquardt damping rule of the outer loop (Sec. 4.6)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hairport.solver.model.progress import ProgressFn

#: the l1 penalty on constraint violation in the merit function is this times the largest multiplier
MERIT_PENALTY_FACTOR = 2.0
#: each backtracking step of the line search shortens the step by this factor ...
BACKTRACK_FACTOR = 0.5
#: ... at most this many times (a strand whose every try raised its merit then stays where it is)
MAX_BACKTRACKS = 6

#: active-set rounds per QP before the last iterate is taken (they converge in a few)
MAX_ACTIVE_SET_ROUNDS = 50
#: a group stops once this many iterations in a row lowered its merit by less than the energy
#: tolerance: one short, backtracked step says little about the minimum
STALLED_ITERATIONS = 2

#: radial damping of Eq. 7's curvature model (see energies.shape_blocks): start, bounds, factor
INITIAL_RADIAL_DAMPING = 1.0
MIN_RADIAL_DAMPING = 1e-4
MAX_RADIAL_DAMPING = 1.0
DAMPING_FACTOR = 4.0
#: a step whose actual merit decrease is below this share of the model's prediction raises the
#: damping (the model was too optimistic) ...
DAMPING_RAISE_BELOW = 0.25
#: ... and one above this share lowers it
DAMPING_LOWER_ABOVE = 0.75

#: a trial point whose distance to the body is proven at least ``eps_c`` plus this (m) from its
#: particle's last query gets no query of its own in the uncoupled line search
#: (:class:`.constraints.QueryAnchors`; a QP step that reaches such a particle's slack is solved
#: again with exact distances). On Table 4's 10^6 groom the fine level asked about 7.5 M points
#: instead of 24 M, in 6.5 s instead of 8.6 (2 mm: 6.9 s, fewer skipped; 0.5 mm steps are common)
QUERY_MARGIN = 1e-3

#: rounds at most of solving again the strands with a segment through the body (the default of
#: :attr:`SolveOptions.segment_rounds`, :mod:`~hairport.solver.adaptation.segments`)
SEGMENT_ROUNDS = 6
#: outer iterations at most of each such round, from the solve's result: the strands start converged
#: but for the ends of their crossing segments; a round its cap stops pushes them out to their margins
SEGMENT_ITERATIONS = 8

#: how the active-set loop runs over uncoupled strands (a diagonal ``K``, Eq. 14's fine level):
#: on compiled per-strand kernels (:mod:`.fine_solve`), or in numpy, the readable reference
ENGINE_COMPILED = "compiled"
ENGINE_NUMPY = "numpy"
ENGINES = (ENGINE_COMPILED, ENGINE_NUMPY)

#: the stage under which the solvers report progress (``progress(stage, fraction, message)``)
SOLVE_STAGE = "solve"


class Cancelled(RuntimeError):
    """The caller asked the solve to stop."""


@dataclass(frozen=True)
class SolveOptions:
    """Settings of the outer loop and of OSQP.

    Attributes
    ----------
    eps_c : float
        Clearance of Eq. 13 (m).
    max_iterations : int
        Cap on outer iterations.
    step_tolerance : float
        Converged when no particle moves more than this (m) in an iteration ...
    clearance_tolerance : float
        ... and no free particle is closer than ``eps_c - clearance_tolerance`` (m).
    energy_tolerance : float
        The active-set solver (:mod:`.active_set`) also stops a strand (or the coupled
        hairstyle) whose Eq. 1 merit fell by less than this fraction in an iteration, with
        the clearance kept: the tail of the nonconvex loop creeps by micrometres per
        iteration without visible change. 0 disables the test.
    osqp_eps_abs, osqp_eps_rel : float
        OSQP's stopping tolerances (meters for the constraints).
    osqp_max_iter : int
    query_margin : float
        The uncoupled active-set line search queries a trial point's distance only where its bound from
        the particle's last query is below ``eps_c`` plus this (m; :data:`QUERY_MARGIN`,
        :class:`.constraints.QueryAnchors`); ``inf`` queries every one.
    segment_rounds : int
        Rounds at most of solving again, with margins, the strands that have a segment through the body
        after the loop (:func:`hairport.solver.adaptation.segments.clear_segments`); 0: particles only,
        as in the paper.
    """

    eps_c: float = 5e-4
    max_iterations: int = 30
    step_tolerance: float = 1e-5
    clearance_tolerance: float = 1e-5
    energy_tolerance: float = 0.0
    osqp_eps_abs: float = 1e-7
    osqp_eps_rel: float = 1e-7
    osqp_max_iter: int = 50_000
    query_margin: float = QUERY_MARGIN
    segment_rounds: int = SEGMENT_ROUNDS


@dataclass
class SolveReport:
    """What one outer loop did, by either QP backend (one level; see :class:`.multiscale.MultiscaleReport`
    for two). The job report's ``solver`` entry is its :func:`dataclasses.asdict`.

    Attributes
    ----------
    backend : str
        ``"active-set"`` or ``"osqp"`` (:data:`.solve.QP_BACKENDS`).
    iterations : int
        Outer iterations run.
    converged : bool
    max_step : list of float
        Per iteration, the longest particle move (m).
    min_clearance : list of float
        Per iteration, the smallest signed distance of a free particle (m).
    step_fractions : list of float
        Per iteration, the (shortest) step length the line search took.
    pushed_out : int
        Particles pushed out after the iteration cap (:func:`.constraints.push_out_short`).
    seconds : float
    groups, converged_groups : int
        Active-set only: independent problems (1 when strands are coupled, else one per
        strand) and how many of them converged.
    open_groups, active_set_rounds, cg_steps : list of int
        Active-set only, per iteration: groups still open, active-set rounds of the QP,
        conjugate-gradient steps.
    merit : list of float
        Active-set only, per iteration: Eq. 1 plus the clearance penalty after the step.
    stopped : list of int
        Active-set only, per iteration: the groups that stopped after it (how many iterations each
        strand took, when strands are groups).
    capped : int
        Active-set only: groups still open when the iteration cap stopped the loop.
    segments_crossing, segment_rounds, segments_left : int
        Segments through the body after the loop, rounds of solving their strands again with margins,
        segments through it after them (:mod:`hairport.solver.adaptation.segments`).
    segment_seconds : float
        The time those checks and rounds took (part of ``seconds``).
    osqp_status : list of str
    osqp_iterations : list of int
        OSQP only, per iteration: OSQP's status and iterations.
    """

    backend: str = ""
    iterations: int = 0
    converged: bool = False
    max_step: list[float] = field(default_factory=list)
    min_clearance: list[float] = field(default_factory=list)
    step_fractions: list[float] = field(default_factory=list)
    pushed_out: int = 0
    seconds: float = 0.0
    groups: int = 0
    converged_groups: int = 0
    stopped: list[int] = field(default_factory=list)
    capped: int = 0
    segments_crossing: int = 0
    segment_rounds: int = 0
    segments_left: int = 0
    segment_seconds: float = 0.0
    open_groups: list[int] = field(default_factory=list)
    active_set_rounds: list[int] = field(default_factory=list)
    cg_steps: list[int] = field(default_factory=list)
    merit: list[float] = field(default_factory=list)
    osqp_status: list[str] = field(default_factory=list)
    osqp_iterations: list[int] = field(default_factory=list)

    def end_iteration(self, iteration: int, merit: np.ndarray, fraction: np.ndarray, done: np.ndarray,
                      max_step: np.ndarray, min_clearance: float, still_open: int, max_iterations: int,
                      progress: ProgressFn | None) -> None:
        """Record one active-set iteration (merits ``(G,)`` after the step, step lengths, the
        groups ``done (G,) bool``, their longest moves, the smallest clearance) and report progress."""
        self.merit.append(float(merit.sum()))
        self.step_fractions.append(float(fraction.min(initial=1.0)))
        self.converged_groups += int(done.sum())
        self.stopped.append(int(done.sum()))
        self.max_step.append(float(max_step.max(initial=0.0)))
        self.min_clearance.append(float(min_clearance))
        self.iterations = iteration + 1
        if progress is not None:
            progress(SOLVE_STAGE, (iteration + 1) / max_iterations,
                     f"iteration {iteration + 1}: max step {self.max_step[-1]:.2e} m, {still_open} open")


def adapt_damping(damping: np.ndarray | float, actual: np.ndarray | float, predicted: np.ndarray | float) -> np.ndarray:
    """Levenberg-Marquardt update of the radial damping from a step's actual and predicted merit change.

    The ratio ``actual / predicted`` (0 where the model predicted no decrease) says how well
    the damped model foresaw the step: below :data:`DAMPING_RAISE_BELOW` the damping grows by
    :data:`DAMPING_FACTOR` (up to :data:`MAX_RADIAL_DAMPING`), above :data:`DAMPING_LOWER_ABOVE`
    it shrinks by it (down to :data:`MIN_RADIAL_DAMPING`), otherwise it stays.

    Parameters
    ----------
    damping : (G,) float64 or float
        Current damping per group (strand, or the coupled hairstyle).
    actual : (G,) float64 or float
        Merit after the full step minus merit before (negative: decrease).
    predicted : (G,) float64 or float
        The same change predicted by the QP's quadratic model.

    Returns
    -------
    damping : (G,) float64 (0-d for scalar inputs)
    """
    predicted = np.asarray(predicted, dtype=np.float64)
    descent = predicted < 0
    ratio = np.where(descent, actual / np.where(descent, predicted, -1.0), 0.0)
    return np.where(
        ratio < DAMPING_RAISE_BELOW,
        np.minimum(MAX_RADIAL_DAMPING, damping * DAMPING_FACTOR),
        np.where(ratio > DAMPING_LOWER_ABOVE, np.maximum(MIN_RADIAL_DAMPING, damping / DAMPING_FACTOR), damping),
    )


def groups_done(
    options: SolveOptions,
    merit_now: np.ndarray,
    merit_trial: np.ndarray,
    failed: np.ndarray,
    small_steps: np.ndarray,
    max_step: np.ndarray,
    shortfall: np.ndarray,
    predicted: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The outer loop's stopping rule for the open groups (strands, or the coupled hairstyle).

    A group is done when its clearance holds (``shortfall <= clearance_tolerance``) and either
    its step was below ``step_tolerance`` (and its line search did not fail), or it stalled:
    :data:`STALLED_ITERATIONS` small merit decreases in a row (below ``energy_tolerance`` of the
    merit; a failed line search counts as one), or, given the QP's ``predicted`` change
    (uncoupled strands), one small decrease that the model also predicted small.

    Parameters
    ----------
    merit_now, merit_trial : (G,) float64
        Merit before and after the step.
    failed : (G,) bool
        Groups whose line search found no lower merit.
    small_steps : (G,) int64
        Consecutive small decreases so far.
    max_step, shortfall : (G,) float64
        Longest particle move (m), most clearance short of ``eps_c`` (m).
    predicted : (G,) float64, optional
        The QP model's merit change.

    Returns
    -------
    done : (G,) bool
    small_steps : (G,) int64
        Updated.
    """
    threshold = options.energy_tolerance * np.abs(merit_now)
    decrease = merit_now - merit_trial
    small = ((decrease >= 0) & (decrease < threshold)) | failed
    small_steps = np.where(small, small_steps + 1, 0)
    stalled = small_steps >= STALLED_ITERATIONS
    if predicted is not None:
        stalled |= small & (-predicted < threshold)
    done = (((max_step < options.step_tolerance) & ~failed) | stalled) & (shortfall <= options.clearance_tolerance)
    return done, small_steps
