"""The active-set loop's level in numpy (:mod:`~hairport.solver.adaptation.loop.active_set`): any ``K``.

The Newton Hessian of Eq. 1 is ``S + 2 alpha K^T G K + 2 beta G`` (``G = diag(gamma)``): ``S``,
Eq. 7's per-segment 3x3 blocks (:func:`~hairport.solver.adaptation.problem.energies.shape_blocks`),
is block-tridiagonal along each strand; ``K`` (Eq. 10) couples a particle with its kNN on other
strands. Each iteration builds that system over the open strands
(:func:`~hairport.solver.adaptation.problem.strand_problem.newton_system`) and solves its QP by the
primal-dual active-set method of :mod:`.contact_qp`.

Coupled strands (the guides of the multi-scale solve, the ``global`` method) are one group: one QP
for all of them, one convergence test. When no entry of ``K`` links two strands every strand is a
group of its own, with its own merit penalty (so a strand's result does not depend on the strands
solved with it), and this level, on a copy of the open strands' problem each iteration, is the
tested reference of the compiled fine level (:mod:`~hairport.solver.adaptation.fine.fine_solve`).

Convention: particles ``(N, 3) float64`` in meters, strands in CSR layout (``offsets``), vectors
particle-major.
"""

from __future__ import annotations

import numpy as np

from hairport.solver.adaptation.coupled.contact_qp import solve_qp
from hairport.solver.adaptation.loop.active_set import NewtonStep, StepOutcome
from hairport.solver.adaptation.loop.options import MERIT_PENALTY_FACTOR, SolveOptions
from hairport.solver.adaptation.problem.constraints import BodyDistance, QueryAnchors, linearised_clearance, reaching
from hairport.solver.adaptation.problem.energies import EnergyWeights
from hairport.solver.adaptation.problem.strand_problem import (
    NewtonSystem,
    StrandProblem,
    compiled_newton_system,
    group_energies,
    newton_system,
    strand_energies,
)


class NumpyLevel:
    """One solve's iterate and per-iteration state over a :class:`StrandProblem`, stepped by
    :func:`~hairport.solver.adaptation.loop.active_set.run_active_set` (see
    :class:`~hairport.solver.adaptation.loop.active_set.ActiveSetLevel` for the methods).

    Parameters
    ----------
    problem : StrandProblem
    body : BodyDistance
        Over the target body.
    weights : EnergyWeights
    options : SolveOptions
    start : (N, 3) float64, optional
        First iterate (``problem.initial`` by default).
    """

    def __init__(self, problem: StrandProblem, body: BodyDistance, weights: EnergyWeights, options: SolveOptions,
                 start: np.ndarray | None = None):
        self.problem, self.body, self.weights, self.options = problem, body, weights, options
        self.points = np.array(problem.initial if start is None else start, dtype=np.float64)
        self.fixed = problem.fixed
        self.coupled = problem.coupled
        self.n_strands = problem.n_strands
        self.n_groups = 1 if self.coupled else problem.n_strands
        self.active_set = np.zeros(problem.n_particles, dtype=bool)
        self.distance, self.normal, self.near = body(self.points)
        self.anchors = QueryAnchors(self.points, self.distance, self.normal, self.near)
        # coupled, a step that reaches a bounded particle's slack means the whole QP again: at 300
        # guides that doubled the CG steps and cost more than the queries it saved (0.25 s at 10^6)
        self.query_margin = np.inf if self.coupled else options.query_margin
        self.penalty = np.zeros(self.n_groups)  # the merit's l1 penalty, each group's own running maximum

    def newton_step(self, open_groups: np.ndarray, damping: np.ndarray) -> NewtonStep:
        problem, options, weights, coupled = self.problem, self.options, self.weights, self.coupled
        if coupled:
            sub, index = problem, np.arange(problem.n_particles)
            group = np.zeros(problem.n_particles, dtype=np.int64)
        else:
            sub, index = problem.subset(open_groups)
            group = sub.strand_of
        k = len(open_groups)
        p = self.points[index]
        dist, normal, near = self.distance[index], self.normal[index], self.near[index]
        strands = np.arange(problem.n_strands) if coupled else open_groups
        system = compiled_newton_system(sub, p, weights, damping[strands]) if coupled else \
            newton_system(sub, p, weights, damping[strands][sub.strand_of])
        step, multipliers, rounds, cg_steps = self._contact_qp(system, sub, index, p, dist, normal, near)
        largest = np.zeros(k)
        np.maximum.at(largest, group, np.abs(multipliers))
        self.penalty[open_groups] = np.maximum(self.penalty[open_groups], MERIT_PENALTY_FACTOR * largest)
        particle_penalty = self.penalty[open_groups][group]
        model_change = np.sum(step * (system.gradient + 0.5 * system.matvec(step)), axis=1)
        strand_predicted = np.bincount(sub.strand_of, model_change, minlength=sub.n_strands)
        if coupled:
            strand_merit_now = self._strand_merits(p, dist)
            merit_now = np.array([strand_merit_now.sum()])
        else:  # a group is a strand: the per-strand merits are the group merits
            merit_now = strand_merit_now = group_energies(sub, p, weights, group, k, particle_penalty, dist,
                                                          options.eps_c)
        self.sub, self.index, self.group, self.k, self.p, self.step = sub, index, group, k, p, step
        self.dist, self.normal_at, self.near_at = dist, normal, near
        self.particle_penalty, self.strand_merit_now = particle_penalty, strand_merit_now
        self.trial = p.copy()
        self.trial_dist, self.trial_normal, self.trial_near = dist.copy(), normal.copy(), near.copy()
        self.queried = np.zeros(len(p), dtype=bool)
        return NewtonStep(strands, merit_now, strand_merit_now, strand_predicted, rounds, cg_steps)

    def _contact_qp(self, system: NewtonSystem, sub: StrandProblem, index: np.ndarray, p: np.ndarray, dist: np.ndarray,
                    normal: np.ndarray, near: np.ndarray) -> tuple[np.ndarray, np.ndarray, int, int]:
        """The QP under the linearised clearance: ``step (n, 3)``, multipliers ``(n,)``, rounds, CG steps.

        A step that reaches a bounded particle's slack (:class:`QueryAnchors`) has its strand's
        bounded particles queried (``dist``, ``normal``, ``near`` updated in place) and the QP solved
        again (uncoupled, the other strands' steps come out the same)."""
        options, anchors = self.options, self.anchors
        cg_steps = 0
        while True:
            constrained, lower = linearised_clearance(dist, options.eps_c, sub.fixed, near)
            step, multipliers, active, rounds, steps = solve_qp(
                system, sub.fixed, constrained, normal, lower, self.active_set[index]
            )
            cg_steps += steps
            hit = reaching(step, dist, anchors.bounded[index], options.eps_c)
            if not hit.any():
                break
            again = np.isin(sub.strand_of, np.unique(sub.strand_of[hit])) & anchors.bounded[index]
            dist[again], normal[again], near[again] = anchors.refresh(self.body, index[again], p[again])
            rows = index[again]
            self.distance[rows], self.normal[rows], self.near[rows] = dist[again], normal[again], near[again]
        self.active_set[index] = active
        return step, multipliers, rounds, cg_steps

    def trial_merits(self, fraction: np.ndarray, accepted: np.ndarray) -> np.ndarray:
        sub, options, eps_c = self.sub, self.options, self.options.eps_c
        todo = ~accepted[sub.strand_of]
        moved = self.p[todo] + fraction[sub.strand_of][todo, None] * self.step[todo]
        d, nrm, nr, asked = self.anchors.trial_distance(self.body, moved, self.index[todo], eps_c, self.query_margin)
        short = nr & (d < eps_c) & ~sub.fixed[todo]  # all of them queried: their bound is short
        if short.any():
            # second-order correction: the linearised half-spaces ignore the body's curvature, and
            # without it the loop zig-zags along the surface
            moved[short] += (eps_c - d[short])[:, None] * nrm[short]
            d2, nrm2, nr2 = self.body(moved[short], self.index[todo][short])
            d[short], nrm[short], nr[short] = d2, nrm2, nr2
        self.trial[todo] = moved
        self.trial_dist[todo], self.trial_normal[todo], self.trial_near[todo] = d, nrm, nr
        self.queried[todo] = asked
        self.strand_merit_trial = self._strand_merits(self.trial, self.trial_dist) if self.coupled else group_energies(
            sub, self.trial, self.weights, sub.strand_of, sub.n_strands, self.particle_penalty, self.trial_dist,
            options.eps_c)
        return self.strand_merit_trial

    def _strand_merits(self, points: np.ndarray, distance: np.ndarray) -> np.ndarray:
        """Coupled: each strand's merit ``(S,)`` at ``points (N, 3)`` by the compiled kernel (one penalty for all:
        the group's)."""
        return strand_energies(self.problem, points, self.weights, float(self.penalty[0]), distance,
                               self.options.eps_c)

    def keep(self, accepted: np.ndarray) -> None:
        """Nothing: the trial points stay in the trial arrays until :meth:`settle`."""

    def settle(self, stays: np.ndarray) -> StepOutcome:
        sub, index, trial, trial_dist = self.sub, self.index, self.trial, self.trial_dist
        strand_merit_trial = self.strand_merit_trial
        if stays.any():
            stay = stays[sub.strand_of]
            trial[stay], trial_dist[stay] = self.p[stay], self.dist[stay]
            self.trial_normal[stay], self.trial_near[stay] = self.normal_at[stay], self.near_at[stay]
            strand_merit_trial = np.where(stays, self.strand_merit_now, strand_merit_trial) if not self.coupled \
                else self._strand_merits(trial, trial_dist)
        # coupled, the group failed when every strand stayed
        failed = stays if not self.coupled else np.array([stays.all()])
        moved = ~stays[sub.strand_of]
        self.anchors.commit(index[moved], trial[moved], trial_dist[moved], self.trial_normal[moved],
                            self.trial_near[moved], self.queried[moved])
        merit_trial = np.array([strand_merit_trial.sum()]) if self.coupled else strand_merit_trial
        moved_by = np.linalg.norm(trial - self.p, axis=1)
        self.points[index] = trial
        self.distance[index], self.normal[index], self.near[index] = trial_dist, self.trial_normal, self.trial_near
        max_step = np.zeros(self.k)
        np.maximum.at(max_step, self.group, moved_by)
        shortfall = np.full(self.k, -np.inf)
        np.maximum.at(shortfall, self.group, np.where(sub.fixed, -np.inf, self.options.eps_c - trial_dist))
        min_clearance = np.min(np.where(sub.fixed, np.inf, trial_dist), initial=np.inf)
        return StepOutcome(merit_trial, failed, max_step, shortfall, min_clearance)
