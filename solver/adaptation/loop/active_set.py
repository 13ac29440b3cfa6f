"""Eq. 1 under Eq. 12-13 by sequential QPs (Sec. 4.6): the one outer loop of the active-set solver.

Each outer iteration takes a projected-Newton step under the linearised contact constraints
(a QP solved by a primal-dual active-set method), then a backtracking line search on the
merit (Eq. 1 plus an l1 penalty on clearance short of ``eps_c``), strand by strand; groups
of strands (the coupled hairstyle, or each strand on its own) leave the loop when their step
or their merit decrease is small, and particles a capped loop leaves short of the clearance
are pushed out. The loop is written once, here (:func:`run_active_set`); what depends on
the level is behind :class:`ActiveSetLevel`:

* :class:`~hairport.solver.adaptation.coupled.numpy_level.NumpyLevel`: any ``K`` in numpy
  (the coupled system and its QP, :mod:`~hairport.solver.adaptation.coupled.contact_qp`): one
  group for coupled strands, one per strand for uncoupled ones, where it is the tested
  reference of
* :class:`~hairport.solver.adaptation.fine.fine_solve.CompiledLevel`: a diagonal ``K`` (Eq. 14's
  fine level) on batched per-strand compiled kernels.

Why every strand backtracks on its own share of the merit (its particles' terms of Eq. 1, the
coupling included), coupled or not: with one step length for all, a few overshooting strands
cut every step to a quarter or less, and at 10^6 particles (300 guides of 100) the guides ended
the 30 iterations at merit 901 where per-strand steps reach 888, 18 % faster.

Convention: particles ``(N, 3) float64`` in meters, strands in CSR layout (``offsets``); ``G``
open groups and ``S`` strands in play in an iteration (the same ones when uncoupled).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from hairport.solver.adaptation.loop.options import (
    BACKTRACK_FACTOR,
    INITIAL_RADIAL_DAMPING,
    MAX_BACKTRACKS,
    Cancelled,
    SolveOptions,
    SolveReport,
    adapt_damping,
    groups_done,
)
from hairport.solver.adaptation.problem.constraints import BodyDistance, push_out_short
from hairport.solver.model.progress import ProgressFn

#: this solver's name in :data:`hairport.solver.adaptation.solve.QP_BACKENDS` and in its reports
BACKEND = "active-set"


@dataclass(frozen=True, eq=False)
class NewtonStep:
    """A level's step of one outer iteration, as the line search needs it.

    Attributes
    ----------
    strands : (S,) int64
        The strands in play (ids in the problem): every strand when coupled, the open ones otherwise.
    merit : (G,) float64
        Each open group's merit at the iterate.
    strand_merit : (S,) float64
        Each strand's share of it (the group's own merit when groups are strands).
    predicted : (S,) float64
        The QP model's merit change of each strand's step.
    rounds, cg_steps : int
        Active-set rounds and conjugate-gradient steps the QP took.
    """

    strands: np.ndarray
    merit: np.ndarray
    strand_merit: np.ndarray
    predicted: np.ndarray
    rounds: int
    cg_steps: int


@dataclass(frozen=True, eq=False)
class StepOutcome:
    """Where an iteration left the open groups.

    Attributes
    ----------
    merit : (G,) float64
        Merit after the step.
    failed : (G,) bool
        Groups whose line search found no lower merit (they stayed).
    max_step, shortfall : (G,) float64
        Longest particle move (m) and most clearance short of ``eps_c`` (m).
    min_clearance : float
        Smallest signed distance of a free particle of the open groups (m).
    """

    merit: np.ndarray
    failed: np.ndarray
    max_step: np.ndarray
    shortfall: np.ndarray
    min_clearance: float


class ActiveSetLevel(Protocol):
    """What :func:`run_active_set` asks of a level: the Newton/QP step, the trial points of the
    line search and the commit of its outcome, over the level's own iterate.

    Attributes
    ----------
    n_groups : int
        Independent problems: 1 when strands are coupled, else one per strand.
    n_strands : int
    coupled : bool
        Whether strands are coupled; an uncoupled strand is a group that also stops after one small
        decrease its QP model predicted small (:func:`~.options.groups_done`).
    points : (N, 3) float64
        The iterate.
    fixed : (N,) bool
    distance : (N,) float64
        The iterate's signed distance to the body (a bound where it was not queried).
    body : BodyDistance
    """

    n_groups: int
    n_strands: int
    coupled: bool
    points: np.ndarray
    fixed: np.ndarray
    distance: np.ndarray
    body: BodyDistance

    def newton_step(self, open_groups: np.ndarray, damping: np.ndarray) -> NewtonStep:
        """The QP step of the ``open_groups (G,) int64`` at the iterate, with the radial damping of each strand
        ``(n_strands,)``; also each strand's merit penalty and the merits at the iterate."""

    def trial_merits(self, fraction: np.ndarray, accepted: np.ndarray) -> np.ndarray:
        """The strands not yet ``accepted (S,) bool`` moved by ``fraction (S,)`` of their step (clearance
        restored along the normal): every strand's merit ``(S,)`` at the trial points."""

    def keep(self, accepted: np.ndarray) -> None:
        """The line search's decision after a trial: ``accepted (S,) bool``."""

    def settle(self, stays: np.ndarray) -> StepOutcome:
        """Commit the iteration: the strands that ``stays (S,) bool`` keep the iterate, the others their
        accepted trial points."""


def run_active_set(
    level: ActiveSetLevel,
    options: SolveOptions = SolveOptions(),
    progress: ProgressFn | None = None,
    should_stop: Callable[[], bool] | None = None,
    began: float | None = None,
) -> tuple[np.ndarray, SolveReport]:
    """Minimise Eq. 1 under Eq. 12-13 over ``level`` by sequential QPs (Sec. 4.6).

    Each outer iteration: the level's projected-Newton QP, then backtracking on each strand's
    share of the merit (:func:`line_search`); a strand whose every trial raised it stays where it
    is. A group stops when no particle moved more than ``step_tolerance`` or its merit fell by less
    than ``energy_tolerance`` (relative) in :data:`~.options.STALLED_ITERATIONS` iterations in a
    row, with its clearance kept; an uncoupled strand also after one such iteration its QP predicted
    too, and a failed line search counts as one. A loop stopped by the cap pushes out the particles
    short of the clearance (:func:`~hairport.solver.adaptation.problem.constraints.push_out_short`).

    Parameters
    ----------
    level : ActiveSetLevel
    options : SolveOptions
    progress : ProgressFn, optional
        ``progress("solve", fraction, message)`` after every outer iteration.
    should_stop : callable() -> bool, optional
        Polled once per outer iteration; True raises :class:`~.options.Cancelled`.
    began : float, optional
        ``time.perf_counter()`` when the solve began (the level's set-up counts); now by default.

    Returns
    -------
    points : (N, 3) float64
    report : SolveReport
        With the active-set fields (``groups``, ``active_set_rounds``, ...).
    """
    began = time.perf_counter() if began is None else began
    report = SolveReport(backend=BACKEND, groups=level.n_groups)
    # the damping is per strand, coupled or not: one strand that turns far must not stiffen
    # every other strand's segments
    damping = np.full(level.n_strands, INITIAL_RADIAL_DAMPING)
    open_groups = np.arange(level.n_groups, dtype=np.int64)
    small_steps = np.zeros(level.n_groups, dtype=np.int64)  # consecutive iterations below the energy tolerance
    for iteration in range(options.max_iterations):
        if len(open_groups) == 0:
            break
        if should_stop is not None and should_stop():
            raise Cancelled("solve cancelled")
        step = level.newton_step(open_groups, damping)
        report.active_set_rounds.append(step.rounds)
        report.cg_steps.append(step.cg_steps)
        report.open_groups.append(len(open_groups))
        fraction, accepted = line_search(level, step, damping)
        # a strand whose every trial raised its merit stays where it is (and, uncoupled, the
        # iteration counts towards its stall): the shortest step taken anyway made such strands
        # oscillate until the cap
        stays = ~accepted
        fraction = np.where(stays, 0.0, fraction)
        outcome = level.settle(stays)
        done, small_steps[open_groups] = groups_done(
            options, step.merit, outcome.merit, outcome.failed, small_steps[open_groups], outcome.max_step,
            outcome.shortfall,
            # one small decrease suffices where the QP's model also predicted a small one
            None if level.coupled else step.predicted)
        open_groups = open_groups[~done]
        report.end_iteration(iteration, outcome.merit, fraction, done, outcome.max_step, outcome.min_clearance,
                             len(open_groups), options.max_iterations, progress)
    report.converged = len(open_groups) == 0
    report.capped = len(open_groups)
    points = level.points
    if not report.converged:
        points, report.pushed_out = push_out_short(
            points, level.fixed, level.distance, level.body.query, options.eps_c, options.clearance_tolerance,
            level.body.margin,
        )
    report.seconds = time.perf_counter() - began
    return points, report


def line_search(level: ActiveSetLevel, step: NewtonStep, damping: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Backtrack each strand on its own merit share: ``(fraction (S,), accepted (S,) bool)``.

    One strand whose Newton step overshoots must not shorten every other strand's step. Coupled,
    a strand's merit holds its share of the coupling, so every strand is judged again after each
    trial (one whose neighbours' backtracking raised it backtracks in turn; all strands' merits
    down means the total is down); uncoupled, an accepted strand is done. The first trial, the
    full step, also updates each strand's radial ``damping`` (:func:`~.options.adapt_damping`).
    """
    fraction = np.ones(len(step.strand_merit))
    accepted = np.zeros(len(fraction), dtype=bool)
    for attempt in range(MAX_BACKTRACKS):
        merit = level.trial_merits(fraction, accepted)
        if attempt == 0:
            damping[step.strands] = adapt_damping(damping[step.strands], merit - step.strand_merit, step.predicted)
        lowered = merit <= step.strand_merit
        accepted = lowered if level.coupled else accepted | lowered
        level.keep(accepted)
        if accepted.all() or attempt == MAX_BACKTRACKS - 1:
            break
        fraction = np.where(accepted, fraction, BACKTRACK_FACTOR * fraction)
    return fraction, accepted
