"""Eq. 1 under Eq. 12-13 by sequential QPs (Sec. 4.6): the outer loop of the active-set solver.

The Newton Hessian of Eq. 1 is ``S + 2 alpha K^T G K + 2 beta G`` (``G = diag(gamma)``):
``S``, Eq. 7's per-segment 3x3 blocks (:func:`.energies.shape_blocks`), is block-tridiagonal
along each strand; ``K`` (Eq. 10) couples a particle with its kNN on other strands. Each outer
iteration solves a QP by the primal-dual active-set method of :mod:`.contact_qp`, then a
backtracking line search on the merit.

When no entry of ``K`` links two strands every strand is its own problem: each gets its own
backtracking line search, damping and convergence test, and leaves the loop when done.
Coupled problems solve one QP for all strands but still backtrack strand by strand, on each
strand's share of the merit (its particles' terms of Eq. 1, the coupling included): with one
step length for all, a few overshooting strands cut every step to a quarter or less, and at
10^6 particles (300 guides of 100) the guides ended the 30 iterations at merit 901 where
per-strand steps reach 888, 18 % faster. The constraints are those of :mod:`.constraints`,
shared with the OSQP backend.

Convention: particles ``(N, 3) float64`` in meters, strands in CSR layout (``offsets``),
vectors particle-major.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from hairport.solver.adaptation.constraints import (
    BodyDistance,
    QueryAnchors,
    linearised_clearance,
    push_out_short,
    reaching,
)
from hairport.solver.adaptation.contact_qp import solve_qp
from hairport.solver.adaptation.energies import EnergyWeights
from hairport.solver.adaptation.fine_solve import pull_weights, solve_uncoupled
from hairport.solver.adaptation.options import (
    BACKTRACK_FACTOR,
    ENGINE_COMPILED,
    ENGINES,
    INITIAL_RADIAL_DAMPING,
    MAX_BACKTRACKS,
    MERIT_PENALTY_FACTOR,
    Cancelled,
    SolveOptions,
    SolveReport,
    adapt_damping,
    groups_done,
)
from hairport.solver.adaptation.strand_problem import StrandProblem, group_energies, newton_system
from hairport.solver.model.progress import ProgressFn

#: this backend's name in :data:`.coupled.QP_BACKENDS` and in its reports
BACKEND = "active-set"
def solve_strands(
    problem: StrandProblem,
    distance: BodyDistance,
    weights: EnergyWeights = EnergyWeights(),
    options: SolveOptions = SolveOptions(),
    start: np.ndarray | None = None,
    progress: ProgressFn | None = None,
    should_stop: Callable[[], bool] | None = None,
    engine: str = ENGINE_COMPILED,
) -> tuple[np.ndarray, SolveReport]:
    """Minimise Eq. 1 under Eq. 12-13 by sequential QPs (Sec. 4.6).

    Each outer iteration: the projected-Newton QP (:func:`solve_qp`), then backtracking on
    Eq. 1 plus an l1 penalty on clearance short of ``eps_c``, with a second-order correction
    (particles a step leaves short of ``eps_c`` are projected back out along the normal:
    the linearised half-spaces ignore the body's curvature, and without it the loop zig-zags
    along the surface); each strand backtracks on its own share of the merit, and a strand
    whose every trial raised it stays where it is. Uncoupled strands each run this loop on their own, with their own
    merit penalty (so a strand's result does not depend on the strands solved with it); with
    a diagonal ``K`` the compiled loop of :mod:`.fine_solve` runs it unless ``engine`` asks
    for this numpy code, its reference.

    A group stops when no particle moved more than ``step_tolerance`` or its merit fell by
    less than ``energy_tolerance`` (relative) in :data:`.options.STALLED_ITERATIONS`
    iterations in a row, with its clearance kept. An uncoupled strand also stops after one
    such iteration when its QP predicted a decrease below the tolerance too (the model agrees
    the minimum is near), and when no trial of its line search lowered the merit it stays where
    it is, which counts as such an iteration.

    Parameters
    ----------
    problem : StrandProblem
    distance : BodyDistance
        Over the target body.
    weights : EnergyWeights
    options : SolveOptions
        ``eps_c``, ``max_iterations``, ``step_tolerance``, ``clearance_tolerance``.
    start : (N, 3) float64, optional
        First iterate (``problem.initial`` by default).
    progress : ProgressFn, optional
        ``progress("solve", fraction, message)`` after every outer iteration.
    should_stop : callable() -> bool, optional
        Polled once per outer iteration; True raises :class:`.options.Cancelled`.
    engine : str
        One of :data:`.options.ENGINES`: ``"compiled"`` (a diagonal ``K`` only; others take
        the numpy path) or ``"numpy"``.

    Returns
    -------
    points : (N, 3) float64
    report : SolveReport
        With the active-set fields (``groups``, ``active_set_rounds``, ...).
    """
    if engine not in ENGINES:
        raise ValueError(f"unknown engine {engine!r}; expected one of {', '.join(ENGINES)}")
    if engine == ENGINE_COMPILED and pull_weights(problem.coupling) is not None:
        points, report = solve_uncoupled(problem, distance, weights, options, start, progress, should_stop)
        report.backend = BACKEND
        return points, report
    began = time.perf_counter()
    points = np.array(problem.initial if start is None else start, dtype=np.float64)
    coupled = problem.coupled
    n_groups = 1 if coupled else problem.n_strands
    report = SolveReport(backend=BACKEND, groups=n_groups)
    # the damping is per strand, coupled or not: one strand that turns far must not stiffen
    # every other strand's segments
    damping = np.full(problem.n_strands, INITIAL_RADIAL_DAMPING)
    active_set = np.zeros(problem.n_particles, dtype=bool)
    open_groups = np.arange(n_groups)
    small_steps = np.zeros(n_groups, dtype=np.int64)  # consecutive iterations below the energy tolerance
    dist_all, normal_all, near_all = distance(points)
    anchors = QueryAnchors(points, dist_all, normal_all, near_all)
    # coupled, a step that reaches a bounded particle's slack means the whole QP again: at 300
    # guides that doubled the CG steps and cost more than the queries it saved (0.25 s at 10^6)
    query_margin = np.inf if coupled else options.query_margin
    penalty = np.zeros(n_groups)  # the merit's l1 penalty, each group's own running maximum
    for iteration in range(options.max_iterations):
        if len(open_groups) == 0:
            break
        if should_stop is not None and should_stop():
            raise Cancelled("solve cancelled")
        if coupled:
            sub, index = problem, np.arange(problem.n_particles)
            group = np.zeros(problem.n_particles, dtype=np.int64)
        else:
            sub, index = problem.subset(open_groups)
            group = sub.strand_of
        k = len(open_groups)
        p = points[index]
        dist, normal, near = dist_all[index], normal_all[index], near_all[index]
        strands = np.arange(problem.n_strands) if coupled else open_groups
        system = newton_system(sub, p, weights, damping[strands][sub.strand_of])
        cg_steps = 0
        while True:
            constrained, lower = linearised_clearance(dist, options.eps_c, sub.fixed, near)
            step, multipliers, active, rounds, steps = solve_qp(
                system, sub.fixed, constrained, normal, lower, active_set[index]
            )
            cg_steps += steps
            hit = reaching(step, dist, anchors.bounded[index], options.eps_c)
            if not hit.any():
                break
            # a step reaches a bounded particle's slack: its strand's bounded particles are
            # queried and the QP solved again (uncoupled, the other strands' steps come out the same)
            again = np.isin(sub.strand_of, np.unique(sub.strand_of[hit])) & anchors.bounded[index]
            dist[again], normal[again], near[again] = anchors.refresh(distance, index[again], p[again])
            dist_all[index[again]], normal_all[index[again]], near_all[index[again]] = dist[again], normal[again], near[again]
        active_set[index] = active
        report.active_set_rounds.append(rounds)
        report.cg_steps.append(cg_steps)
        report.open_groups.append(k)
        largest = np.zeros(k)
        np.maximum.at(largest, group, np.abs(multipliers))
        penalty[open_groups] = np.maximum(penalty[open_groups], MERIT_PENALTY_FACTOR * largest)
        particle_penalty = penalty[open_groups][group]
        merit_now = group_energies(sub, p, weights, group, k, particle_penalty, dist, options.eps_c)
        model_change = np.sum(step * (system.gradient + 0.5 * system.matvec(step)), axis=1)
        strand_predicted = np.bincount(sub.strand_of, model_change, minlength=sub.n_strands)
        # uncoupled, a group is a strand: the per-strand merits are the group merits
        strand_merit_now = merit_now if not coupled else group_energies(
            sub, p, weights, sub.strand_of, sub.n_strands, particle_penalty, dist, options.eps_c)

        # the line search backtracks each strand on its own merit, coupled or not: one strand whose
        # Newton step overshoots must not shorten every other strand's step (coupled, a strand's
        # merit holds its share of the coupling, and a strand whose neighbours' backtracking
        # raised it backtracks in turn; all strands' merits down means the total is down)
        fraction = np.ones(sub.n_strands)
        accepted = np.zeros(sub.n_strands, dtype=bool)
        trial = p.copy()
        trial_dist, trial_normal, trial_near = dist.copy(), normal.copy(), near.copy()
        queried = np.zeros(len(p), dtype=bool)
        for attempt in range(MAX_BACKTRACKS):
            todo = ~accepted[sub.strand_of]
            moved = p[todo] + fraction[sub.strand_of][todo, None] * step[todo]
            d, nrm, nr, asked = anchors.trial_distance(distance, moved, index[todo], options.eps_c, query_margin)
            short = nr & (d < options.eps_c) & ~sub.fixed[todo]  # all of them queried: their bound is short
            if short.any():
                moved[short] += (options.eps_c - d[short])[:, None] * nrm[short]
                d2, nrm2, nr2 = distance(moved[short])
                d[short], nrm[short], nr[short] = d2, nrm2, nr2
            trial[todo] = moved
            trial_dist[todo], trial_normal[todo], trial_near[todo] = d, nrm, nr
            queried[todo] = asked
            strand_merit_trial = group_energies(
                sub, trial, weights, sub.strand_of, sub.n_strands, particle_penalty, trial_dist, options.eps_c)
            if attempt == 0:
                damping[strands] = adapt_damping(
                    damping[strands], strand_merit_trial - strand_merit_now, strand_predicted)
            lowered = strand_merit_trial <= strand_merit_now
            accepted = lowered if coupled else accepted | lowered
            if accepted.all() or attempt == MAX_BACKTRACKS - 1:
                break
            fraction = np.where(accepted, fraction, BACKTRACK_FACTOR * fraction)
        # a strand whose every trial raised its merit stays where it is (and, uncoupled, the
        # iteration counts towards its stall): the shortest step taken anyway made such strands
        # oscillate until the cap
        stays = ~accepted
        if stays.any():
            stay = stays[sub.strand_of]
            trial[stay], trial_dist[stay], trial_normal[stay], trial_near[stay] = p[stay], dist[stay], normal[stay], near[stay]
            fraction = np.where(stays, 0.0, fraction)
            strand_merit_trial = np.where(stays, strand_merit_now, strand_merit_trial) if not coupled else group_energies(
                sub, trial, weights, sub.strand_of, sub.n_strands, particle_penalty, trial_dist, options.eps_c)
        failed = stays if not coupled else np.array([fraction.max() == 0.0])
        moved = ~stays[sub.strand_of]
        anchors.commit(index[moved], trial[moved], trial_dist[moved], trial_normal[moved], trial_near[moved],
                       queried[moved])
        merit_trial = np.array([strand_merit_trial.sum()]) if coupled else strand_merit_trial
        points[index] = trial
        dist_all[index], normal_all[index], near_all[index] = trial_dist, trial_normal, trial_near
        moved_by = np.linalg.norm(trial - p, axis=1)
        max_step = np.zeros(k)
        np.maximum.at(max_step, group, moved_by)
        shortfall = np.full(k, -np.inf)
        np.maximum.at(shortfall, group, np.where(sub.fixed, -np.inf, options.eps_c - trial_dist))
        done, small_steps[open_groups] = groups_done(
            options, merit_now, merit_trial, failed, small_steps[open_groups], max_step, shortfall,
            # one small decrease suffices where the QP's model also predicted a small one
            None if coupled else strand_predicted)
        open_groups = open_groups[~done]
        report.end_iteration(iteration, merit_trial, fraction, done, max_step,
                             np.min(np.where(sub.fixed, np.inf, trial_dist), initial=np.inf), len(open_groups),
                             options.max_iterations, progress)
    report.converged = len(open_groups) == 0
    if not report.converged:
        points, report.pushed_out = push_out_short(
            points, problem.fixed, dist_all, distance.query, options.eps_c, options.clearance_tolerance
        )
    report.seconds = time.perf_counter() - began
    return points, report
