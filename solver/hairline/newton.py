"""Projected Newton for the membrane of Eq. 15-17 with the hairline pinned (Sec. 6.1): load
stages, the kinks of the embedded head as an active set (:mod:`.kinks`) and the fold barrier.

:func:`relocate` is the entry point; :class:`ProjectedNewton` holds one solve's state (the
membrane, chart, pinned vertices, orientation and report) and its steps as methods.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from hairport.solver.hairline.fold_barrier import FOLD_STIFFNESS, fold_barrier
from hairport.solver.hairline.head_chart import HeadChart
from hairport.solver.hairline.kinks import FREE, KINK_BARYCENTRIC, ON_EDGE, SNAP_BARYCENTRIC, kink_activity
from hairport.solver.hairline.membrane import (
    Membrane,
    assemble_blocks,
    membrane_energy,
    parameter_blocks,
    position_gradients,
    project_psd,
    shifted_solve,
)
from hairport.solver.mesh.areas import signed_areas
from hairport.solver.mesh.topology import graph_laplacian
from hairport.solver.model.errors import InputError

#: default Newton stopping tolerance on the largest parameter step (uv units); harmonic
#: disk maps span about one uv unit
DEFAULT_STEP_TOLERANCE = 1e-9
#: stop also when the squared Newton decrement ``-g . d`` falls below this share of
#: ``mu * (total rest area)`` (dimensionless; near the round-off of the energy itself)
DECREMENT_TOLERANCE = 1e-15
#: default relative energy decrease of one accepted step below which a stage has stalled
#: (converged): on the piecewise-linear head, vertices that reach a head edge make the
#: step test wait for ever shorter kink-limited steps that no longer change the energy
DEFAULT_ENERGY_TOLERANCE = 1e-7
#: a step cut below this fraction by the line search (a vertex meeting a head edge or the
#: fold barrier) ends the stage once it lowers the energy by less than SHORT_STEP_TOLERANCE
#: of it: such steps repeat at the same fraction for dozens of iterations, moving vertices
#: by micrometres
SHORT_STEP = 0.125
SHORT_STEP_TOLERANCE = 1e-6
#: the same for the intermediate load stages, whose results only start the next stage
STAGE_ENERGY_TOLERANCE = 1e-5
#: default cap on Newton iterations (all load stages together)
DEFAULT_MAX_ITERATIONS = 100
#: step halvings tried by the backtracking line search before giving up
MAX_BACKTRACKS = 40
#: Armijo sufficient-decrease constant (dimensionless)
ARMIJO = 1e-4
#: diagonal shift of the unit-weight graph Laplacian (neighbour counts, ~6) in the
#: harmonic start, so that scalp pieces with no fixed vertex get zero motion
HARMONIC_SHIFT = 1e-12
#: boundary-motion fractions below this are not split further (load stepping, relocate)
MIN_LOAD_FRACTION = 1.0 / 1024.0


@dataclass
class RelocationReport:
    """What :func:`relocate` did.

    Attributes
    ----------
    iterations : int
        Accepted Newton steps, all load stages together.
    converged : bool
        The last stage met the tolerance with the boundary at its target.
    energy : list of float
        Energy (J) at the start of each stage and after every accepted step (moving
        vertices onto kinks between steps only lowers it and is not listed).
    step_sizes : list of float
        Line-search fraction of every accepted step.
    seconds : float
    stages : int
        Load stages (1 unless the boundary motion had to be split to keep triangles unflipped).
    start : list of str
        How each stage's start was made: ``"pinned"`` (free vertices left in place),
        ``"elastic"`` (one Newton step of Eq. 15 with the hairline moved, used when pinning
        alone flips triangles) or ``"harmonic"`` (the boundary motion extended to the free
        vertices by a uniform graph-Laplacian solve, when the elastic start flips too).
    held : list of int
        Per Newton iteration, the free vertices held on a head edge or vertex (a kink of
        the energy where both sides go uphill).
    exact_steps : int
        Accepted steps that used the exact instead of the projected Hessian (``polish``).
    stop : str
        Why the last stage stopped: ``"step"`` (largest step below the tolerance),
        ``"decrement"`` (Newton decrement at round-off), ``"energy"`` (a step lowered the
        energy by less than the relative tolerance), ``"short_steps"`` (a step the line
        search cut below :data:`SHORT_STEP` lowered it by less than
        :data:`SHORT_STEP_TOLERANCE`), ``"line_search"`` (no admissible
        descent along the Newton direction) or ``"iterations"``.
    """

    iterations: int = 0
    converged: bool = False
    energy: list[float] = field(default_factory=list)
    step_sizes: list[float] = field(default_factory=list)
    seconds: float = 0.0
    stages: int = 0
    start: list[str] = field(default_factory=list)
    held: list[int] = field(default_factory=list)
    exact_steps: int = 0
    stop: str = ""


def relocate(
    membrane: Membrane,
    chart: HeadChart,
    u_start: np.ndarray,
    fixed: np.ndarray,
    u_fixed: np.ndarray,
    max_iterations: int = DEFAULT_MAX_ITERATIONS,
    tolerance: float = DEFAULT_STEP_TOLERANCE,
    polish: bool = True,
    energy_tolerance: float = DEFAULT_ENERGY_TOLERANCE,
) -> tuple[np.ndarray, RelocationReport]:
    """Minimise Eq. 15 over the free scalp parameters with the hairline pinned (projected Newton).

    Each iteration solves ``(H + shift I) d = -g`` on the free unknowns with the projected
    Hessian of :func:`.membrane.membrane_hessian` (Teran et al. 2005) and backtracks (halving, at
    most :data:`MAX_BACKTRACKS`) until the trial point keeps every vertex inside the chart,
    every scalp triangle's signed uv area of its sign in ``u_start``, and satisfies Armijo;
    hosts are located anew at every evaluation. Stops when the largest vertex step
    ``|d|`` is below ``tolerance``, the squared Newton decrement ``-g . d`` below
    :data:`DECREMENT_TOLERANCE` ``* mu * sum A_t``, or an accepted step lowered the energy
    by less than ``energy_tolerance`` of it (:data:`STAGE_ENERGY_TOLERANCE` at least for
    intermediate load stages); :attr:`RelocationReport.stop` says which.

    Kinks: ``x(u)`` is only piecewise affine, so ``E(u)`` has kinks along the head's edges,
    where a stretched membrane's minimiser often puts vertices; they are an active set,
    re-decided every iteration (:mod:`.kinks`), and the line search lands exactly on the
    first edge a vertex would cross before halving past it.

    The energy minimised is Eq. 15 plus :func:`.fold_barrier.fold_barrier` (zero unless a
    triangle is compressed ten-fold in uv), which keeps triangles from folding across the
    head's bends.

    The fixed vertices are first set to ``u_fixed``. If that flips a triangle, the boundary
    motion is extended to the free vertices by one elastic Newton step, else by a
    graph-harmonic extension; if those flip too, the motion is applied in load stages
    (halved until a stage starts unflipped, each solved to convergence); ``u[fixed] ==
    u_fixed`` unless ``max_iterations`` ran out first.

    Parameters
    ----------
    membrane : Membrane
    chart : HeadChart
    u_start : (n, 2) float64
        Starting parameters, inside the chart, no degenerate scalp triangle in uv.
    fixed : (n,) bool
        Hairline (Dirichlet) vertices.
    u_fixed : (k, 2) float64
        Their target parameters, ``k = fixed.sum()``, in the order of ``flatnonzero(fixed)``.
    max_iterations : int
        Newton steps, all stages together.
    tolerance : float
        Largest vertex step (uv units) counted as converged.
    energy_tolerance : float
        Relative energy decrease of a step counted as converged.
    polish : bool
        After a full projected step, first try the exact Hessian's full step (kept only if
        it is a descent direction, admissible and passes Armijo). Near a minimiser with
        compressed triangles the per-triangle clamp stays active and projected Newton
        converges only linearly (a contraction of about 0.25 per step measured on a 20 %
        push of a 10x10 sheet); the exact steps restore quadratic convergence.

    Returns
    -------
    u : (n, 2) float64
    report : RelocationReport

    Raises
    ------
    InputError
        On bad shapes, points outside the chart, degenerate starting triangles or a
        boundary motion that cannot be reached without flipping.
    """
    return ProjectedNewton(membrane, chart, u_start, fixed, u_fixed, max_iterations, tolerance, polish,
                           energy_tolerance).run()


class ProjectedNewton:
    """One minimisation of Eq. 15 with the hairline pinned; arguments and refusals as
    :func:`relocate`, which calls :meth:`run`.

    The state shared by the steps: ``free (n,) bool`` (the vertices Newton moves),
    ``orientation (m,)`` (each scalp triangle's uv area sign at the start, which every
    admissible point keeps), ``oriented (m, 3)`` and ``rest_uv (m,)`` (the triangles turned
    counter-clockwise at the start and their uv areas, the fold barrier's reference) and the
    :class:`RelocationReport` filled in as the solve goes.
    """

    def __init__(
        self,
        membrane: Membrane,
        chart: HeadChart,
        u_start: np.ndarray,
        fixed: np.ndarray,
        u_fixed: np.ndarray,
        max_iterations: int = DEFAULT_MAX_ITERATIONS,
        tolerance: float = DEFAULT_STEP_TOLERANCE,
        polish: bool = True,
        energy_tolerance: float = DEFAULT_ENERGY_TOLERANCE,
    ):
        self.began = time.perf_counter()
        u_start = np.asarray(u_start, dtype=np.float64)
        fixed = np.asarray(fixed, dtype=bool)
        u_fixed = np.asarray(u_fixed, dtype=np.float64).reshape(-1, 2)
        n = len(membrane.rest)
        if u_start.shape != (n, 2) or fixed.shape != (n,) or len(u_fixed) != fixed.sum():
            raise InputError("need u_start (n, 2), fixed (n,) and u_fixed (fixed.sum(), 2)", "relocate")
        if (chart.locate(u_start)[0] < 0).any() or (chart.locate(u_fixed)[0] < 0).any():
            raise InputError("starting or hairline parameters lie outside the head chart", "relocate")
        orientation = np.sign(signed_areas(u_start, membrane.triangles))
        if (orientation == 0).any():
            raise InputError("the scalp has degenerate triangles in uv at the start", "relocate")

        self.membrane, self.chart = membrane, chart
        self.u_start, self.fixed, self.u_fixed = u_start, fixed, u_fixed
        self.max_iterations, self.tolerance, self.polish = max_iterations, tolerance, polish
        self.energy_tolerance = energy_tolerance
        self.n = n
        self.free = ~fixed
        self.orientation = orientation
        self.oriented = np.where((orientation < 0)[:, None], membrane.triangles[:, [0, 2, 1]], membrane.triangles)
        self.rest_uv = signed_areas(u_start, self.oriented)
        self.barrier_weights = FOLD_STIFFNESS * membrane.mu * membrane.areas
        self.energy_scale = membrane.mu * float(membrane.areas.sum())
        self.report = RelocationReport()
        self._laplacian: sp.csr_matrix | None = None

    # -- the energy ----------------------------------------------------------------------------

    def admissible(self, u: np.ndarray) -> float | None:
        """Energy (J) at ``u (n, 2)`` if inside the chart and unflipped, else None."""
        if (self.chart.locate(u)[0] < 0).any():
            return None
        if (signed_areas(u, self.membrane.triangles) * self.orientation <= 0).any():
            return None
        energy = membrane_energy(self.membrane, self.chart, u) + self.barrier(u)[0]
        return energy if np.isfinite(energy) else None

    def barrier(self, u: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """:func:`fold_barrier` at ``u (n, 2)``: energy, ``(n, 2)`` gradient, ``(m, 6, 6)`` blocks."""
        return fold_barrier(self.oriented, u, self.rest_uv, self.barrier_weights)

    def derivatives(self, u: np.ndarray, F: np.ndarray, gx: np.ndarray, M: np.ndarray, exact: bool):
        """Gradient ``dE/du (2n,)`` of Eq. 15 plus the fold barrier, its projected Hessian and
        (if ``exact``) its exact one, ``(2n, 2n)``, at deformation gradients ``F (m, 3, 2)``
        and position gradients ``gx (n, 3)`` with host Jacobians ``M (n, 3, 2)``."""
        triangles, n = self.membrane.triangles, self.n
        _, fold_gradient, fold_blocks = self.barrier(u)
        g = (np.einsum("nia,ni->na", M, gx) + fold_gradient).ravel()
        blocks = parameter_blocks(self.membrane, F, M)
        projected = (assemble_blocks(triangles, project_psd(blocks), n)
                     + assemble_blocks(self.oriented, project_psd(fold_blocks), n))
        if not exact:
            return g, projected, None
        return g, projected, assemble_blocks(triangles, blocks, n) + assemble_blocks(self.oriented, fold_blocks, n)

    # -- the start of a load stage ----------------------------------------------------------------

    def elastic_start(self, u: np.ndarray, target: np.ndarray) -> np.ndarray | None:
        """One Newton step of Eq. 15 with the hairline moved to ``target (k, 2)`` (an
        inhomogeneous Dirichlet step): the free vertices follow the boundary motion as the
        linearised membrane does, at the current hosts. None if the step is not finite."""
        free, fixed = self.free, self.fixed
        host, _, x = self.chart.place(u)
        F, gx = position_gradients(self.membrane, x)
        g, H, _ = self.derivatives(u, F, gx, self.chart.jacobians(host), exact=False)
        free2, fixed2 = np.repeat(free, 2), np.repeat(fixed, 2)
        rhs = -(g[free2] + H[free2][:, fixed2] @ (target - u[fixed]).ravel())
        step = shifted_solve(H[free2][:, free2], rhs)
        if not np.isfinite(step).all():
            return None
        extended = u.copy()
        extended[fixed] = target
        extended[free] += step.reshape(-1, 2)
        return extended

    def harmonic_start(self, u: np.ndarray, target: np.ndarray) -> np.ndarray:
        """``u`` with the hairline moved to ``target (k, 2)`` and the motion extended to the
        free vertices by the unit-weight graph Laplacian of the scalp (harmonic in the graph)."""
        free, fixed, n = self.free, self.fixed, self.n
        if self._laplacian is None:
            self._laplacian = graph_laplacian(self.membrane.triangles, n)
        laplacian = self._laplacian
        # a shift keeps components without a pinned vertex (zero motion) solvable
        L_ff = (laplacian[free][:, free] + HARMONIC_SHIFT * sp.identity(int(free.sum()))).tocsc()
        motion = np.zeros((n, 2))
        motion[fixed] = target - u[fixed]
        motion[free] = spla.spsolve(L_ff, -(laplacian[free][:, fixed] @ motion[fixed])).reshape(-1, 2)
        return u + motion

    def stage_start(self, u: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, float, str] | None:
        """The first admissible of the pinned, elastic and harmonic starts with the hairline at
        ``target (k, 2)``: parameters, energy and its name; None if all three flip."""
        pinned = u.copy()
        pinned[self.fixed] = target
        energy = self.admissible(pinned)
        if energy is not None:
            return pinned, energy, "pinned"
        extended = self.elastic_start(u, target)
        energy = None if extended is None else self.admissible(extended)
        if energy is not None:
            return extended, energy, "elastic"
        extended = self.harmonic_start(u, target)
        energy = self.admissible(extended)
        if energy is not None:
            return extended, energy, "harmonic"
        return None

    def next_stage(self, u: np.ndarray, reached: float) -> tuple[np.ndarray, float, float]:
        """Start the next load stage from ``u (n, 2)`` with the hairline ``reached`` of the way:
        the whole remaining motion, else the step toward ``reached`` halved until a start is
        admissible (``InputError`` ``hairline_too_far`` below :data:`MIN_LOAD_FRACTION`).
        Returns the start ``(n, 2)``, its energy and how far the hairline now is (1: there)."""
        base = self.u_start[self.fixed]
        fraction = 1.0
        while True:
            target = self.u_fixed if fraction == 1.0 else base + fraction * (self.u_fixed - base)
            started = self.stage_start(u, target)
            if started is not None:
                break
            fraction = 0.5 * (reached + fraction)
            if fraction - reached < MIN_LOAD_FRACTION:
                raise InputError(
                    f"the hairline edit is too drastic for this scalp: beyond {100 * reached:.0f} % of the "
                    "hairline's motion the scalp would fold over itself on the head; use a smaller amount "
                    "or a curve closer to the current hairline", "relocate", "hairline_too_far")
        u, energy, how = started
        self.report.stages += 1
        self.report.start.append(how)
        self.report.energy.append(energy)
        return u, energy, fraction

    # -- one Newton iteration -----------------------------------------------------------------------

    def linearise(self, u: np.ndarray, energy: float, exact: bool):
        """The Newton system at ``u (n, 2)`` with the vertices in a kink held (:mod:`.kinks`).

        Returns ``u`` (the held vertices snapped onto their edge or vertex when that does not
        raise the energy) and its energy, the reduced gradient ``T^T g (r,)``, the reduced
        projected (then, if ``exact``, exact) Hessians ``(r, r)``, the basis ``T (2n, r)`` of
        the unknowns (2 per free vertex, 1 along the edge per edge-held one), the hosts
        ``(n,)`` and the count of held vertices."""
        chart, free, n = self.chart, self.free, self.n
        host, barycentric, x = self.chart.place(u)
        F, gx = position_gradients(self.membrane, x)
        _, mode, _, snapped = kink_activity(chart, host, barycentric, gx, free, SNAP_BARYCENTRIC)
        if (mode != FREE).any() and not np.array_equal(snapped, u):
            snapped_energy = self.admissible(snapped)
            if snapped_energy is not None and snapped_energy <= energy:
                u, energy = snapped, snapped_energy
                host, barycentric, x = self.chart.place(u)
                F, gx = position_gradients(self.membrane, x)
        host, mode, tangent, _ = kink_activity(chart, host, barycentric, gx, free)
        M = chart.jacobians(host)
        loose = np.flatnonzero(free & (mode == FREE))
        edged = np.flatnonzero(free & (mode == ON_EDGE))
        first = 2 * np.arange(len(loose))
        rows = np.concatenate([2 * loose, 2 * loose + 1, 2 * edged, 2 * edged + 1])
        cols = np.concatenate([first, first + 1] + [2 * len(loose) + np.arange(len(edged))] * 2)
        vals = np.concatenate([np.ones(2 * len(loose)), tangent[edged, 0], tangent[edged, 1]])
        T = sp.csr_matrix((vals, (rows, cols)), shape=(2 * n, 2 * len(loose) + len(edged)))
        g, projected, exact_hessian = self.derivatives(u, F, gx, M, exact)
        gr = T.T @ g
        hessians = [(T.T @ H @ T).tocsc() for H in (projected, exact_hessian) if H is not None]
        return u, energy, gr, hessians, T, host, int((free & (mode != FREE)).sum())

    def direction(self, u: np.ndarray, gr: np.ndarray, Hr: sp.csc_matrix, T: sp.csr_matrix, host: np.ndarray):
        """Newton step ``(n, 2)``, squared decrement ``-g . d`` and the first step fraction at
        which a vertex leaves its host (a kink), for the reduced system ``(Hr, gr)``."""
        n, chart = self.n, self.chart
        if Hr.shape[0] == 0:  # every free vertex held at a head vertex
            return np.zeros((n, 2)), 0.0, np.inf
        z = shifted_solve(Hr, -gr)
        d = (T @ z).reshape(n, 2)
        weights = chart.barycentric(host, u)
        local = np.einsum("nab,nb->na", chart.uv_inverse[host], d)
        rate = np.column_stack([-local.sum(axis=1), local])
        crossing = (weights > KINK_BARYCENTRIC) & (rate < 0)
        first_kink = float(np.where(crossing, weights / np.where(crossing, -rate, 1.0), np.inf).min())
        return d, float(-gr @ z), first_kink

    def small(self, d: np.ndarray, decrement2: float) -> bool:
        """Whether step ``d (n, 2)`` is converged (largest vertex step or decrement); sets the stop."""
        if np.sqrt((d**2).sum(axis=1)).max() < self.tolerance:
            self.report.stop = "step"
            return True
        if decrement2 < DECREMENT_TOLERANCE * self.energy_scale:
            self.report.stop = "decrement"
            return True
        return False

    def finish(self, u: np.ndarray, energy: float, d: np.ndarray) -> tuple[np.ndarray, float]:
        """Take the last step when it is not below the tolerance: the decrement stopped the
        loop because Armijo can no longer be told from round-off; keep the step if it is
        admissible and does not raise the energy."""
        if np.sqrt((d**2).sum(axis=1)).max() < self.tolerance:
            return u, energy
        trial_energy = self.admissible(u + d)
        if trial_energy is None or trial_energy > energy:
            return u, energy
        self.accept(trial_energy, 1.0)
        return u + d, trial_energy

    def accept(self, energy: float, step_size: float) -> None:
        """Count an accepted step in the report."""
        self.report.iterations += 1
        self.report.energy.append(energy)
        self.report.step_sizes.append(step_size)

    def line_search(self, u: np.ndarray, energy: float, d: np.ndarray, decrement2: float, first_kink: float):
        """Backtrack along ``d`` (halving, landing on the first kink rather than halving past
        it) to an admissible Armijo point: ``(fraction, point, energy)``, point None if none."""
        alpha = 1.0
        for _ in range(MAX_BACKTRACKS + 1):
            trial = u + alpha * d
            trial_energy = self.admissible(trial)
            if trial_energy is not None and trial_energy <= energy - ARMIJO * alpha * decrement2:
                return alpha, trial, trial_energy
            alpha = first_kink if 0.5 * alpha <= first_kink < alpha else 0.5 * alpha
        return alpha, None, None

    # -- the solve -----------------------------------------------------------------------------------

    def solve_stage(self, u: np.ndarray, energy: float, final: bool) -> tuple[np.ndarray, bool]:
        """Newton iterations of one load stage from ``u (n, 2)`` at ``energy`` until a stop (see
        :func:`relocate`; stages before the ``final`` one stop at :data:`STAGE_ENERGY_TOLERANCE`
        at least). Returns the parameters ``(n, 2)`` and whether the stage converged."""
        report = self.report
        converged = not self.free.any()
        full_step = False
        stall = self.energy_tolerance if final else max(self.energy_tolerance, STAGE_ENERGY_TOLERANCE)
        report.stop = "step" if converged else "iterations"

        def stalled(before: float, after: float) -> bool:
            return before - after <= stall * abs(before)

        while not converged and report.iterations < self.max_iterations:
            exact = self.polish and full_step
            u, energy, gr, hessians, T, host, held = self.linearise(u, energy, exact)
            report.held.append(held)
            if exact:
                # the exact Hessian's full step, taken only if it is an admissible Armijo descent
                d, decrement2, _ = self.direction(u, gr, hessians[1], T, host)
                if decrement2 > 0:
                    if self.small(d, decrement2):
                        u, energy = self.finish(u, energy, d)
                        converged = True
                        break
                    trial_energy = self.admissible(u + d)
                    if trial_energy is not None and trial_energy <= energy - ARMIJO * decrement2:
                        converged = stalled(energy, trial_energy)
                        u, energy = u + d, trial_energy
                        self.accept(energy, 1.0)
                        report.exact_steps += 1
                        if converged:
                            report.stop = "energy"
                        continue
            d, decrement2, first_kink = self.direction(u, gr, hessians[0], T, host)
            if self.small(d, decrement2):
                u, energy = self.finish(u, energy, d)
                converged = True
                break
            alpha, accepted, trial_energy = self.line_search(u, energy, d, decrement2, first_kink)
            if accepted is None:
                report.stop = "line_search"
                break
            converged = stalled(energy, trial_energy)
            if converged:
                report.stop = "energy"
            elif alpha < SHORT_STEP and energy - trial_energy <= SHORT_STEP_TOLERANCE * abs(energy):
                converged = True
                report.stop = "short_steps"
            u, energy = accepted, trial_energy
            full_step = alpha == 1.0
            self.accept(energy, alpha)
        return u, converged

    def run(self) -> tuple[np.ndarray, RelocationReport]:
        """Load stages until the hairline is at its target or the iterations run out: the
        parameters ``(n, 2)`` and the report."""
        u = self.u_start.copy()
        reached = 0.0
        while True:
            u, energy, reached = self.next_stage(u, reached)
            u, converged = self.solve_stage(u, energy, reached >= 1.0)
            if reached >= 1.0 or self.report.iterations >= self.max_iterations:
                break
        self.report.converged = converged and reached >= 1.0
        self.report.seconds = time.perf_counter() - self.began
        return u, self.report
