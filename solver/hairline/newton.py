"""Projected Newton for the membrane (Eq. 15-17) with the hairline pinned: load stages, kinks of the embedded head, fold barrier."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from hairport.solver.hairline.head_chart import HeadChart
from hairport.solver.hairline.membrane import (
    FOLD_STIFFNESS,
    Membrane,
    _assemble_blocks,
    _parameter_blocks,
    _position_gradients,
    _project_psd,
    _shifted_solve,
    fold_barrier,
    membrane_energy,
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


#: a scalp vertex whose barycentric coordinate in its host is below this lies on the
#: host's edge (one small coordinate) or vertex (two): where the piecewise-linear head
#: bends, the energy has a kink there (see :func:`relocate`)
KINK_BARYCENTRIC = 1e-10
#: a free vertex this close (barycentric) to a head edge or vertex where both sides go
#: uphill is moved onto it when that lowers the energy (Newton would otherwise approach
#: the kink by ever shorter steps)
SNAP_BARYCENTRIC = 1e-6
#: a vertex's activity: free in its host (2 unknowns), held on a head edge (1) or at a
#: head vertex (0)
FREE, ON_EDGE, AT_VERTEX = 0, 1, 2


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
        How each stage's start was made: ``"pinned"`` (free vertices left in place) or
        ``"harmonic"`` (the boundary motion extended to the free vertices by a uniform
        graph-Laplacian solve, used when pinning alone flips triangles).
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


def _activity(
    chart: HeadChart,
    host: np.ndarray,
    barycentric: np.ndarray,
    gx: np.ndarray,
    free: np.ndarray,
    reach: float = KINK_BARYCENTRIC,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Which free vertices sit in a kink of the energy, and which host to differentiate in.

    A vertex on a head edge with both one-sided derivatives across the edge >= 0 is held
    on the edge (``ON_EDGE``, moving along ``tangent``); otherwise it is differentiated in
    the side of steeper descent. A vertex at a head vertex with no descent direction into
    any incident triangle is held there (``AT_VERTEX``); otherwise it is differentiated in
    the incident triangle of steepest descent. Vertices within ``reach`` (barycentric) of
    an edge or vertex are tested as if on it; if held, ``snapped`` puts them on it.

    Parameters
    ----------
    chart : HeadChart
    host : (n,) int64
    barycentric : (n, 3) float64
    gx : (n, 3) float64
        ``dE/dx`` per scalp vertex.
    free : (n,) bool
    reach : float
        Barycentric distance counted as on an edge or vertex.

    Returns
    -------
    host : (n,) int64
        Host to use for the Jacobians.
    mode : (n,) int8
        ``FREE``, ``ON_EDGE`` or ``AT_VERTEX``.
    tangent : (n, 2) float64
        Unit uv direction of the holding edge (``ON_EDGE`` rows), else 0.
    snapped : (n, 2) float64
        Parameters with the held vertices moved exactly onto their edge or vertex.
    """
    n = len(host)
    host = host.copy()
    mode = np.zeros(n, dtype=np.int8)
    tangent = np.zeros((n, 2))
    faces, uv = chart.faces, chart.uv
    snapped = np.einsum("nk,nkc->nc", barycentric, uv[faces[host]])
    small = barycentric < reach
    on = barycentric < KINK_BARYCENTRIC
    count = small.sum(axis=1)

    # on an edge: the corner k with the small coordinate faces it
    idx = np.flatnonzero(free & (count == 1))
    if len(idx):
        t = host[idx]
        k = np.argmax(small[idx], axis=1)
        c1 = faces[t, (k + 1) % 3]
        c2 = faces[t, (k + 2) % 3]
        edge = uv[c2] - uv[c1]
        unit = edge / np.linalg.norm(edge, axis=1, keepdims=True)
        normal = np.column_stack([-unit[:, 1], unit[:, 0]])
        normal *= np.sign(np.einsum("ij,ij->i", normal, uv[faces[t, k]] - uv[c1]))[:, None]  # into t
        slope_in = np.einsum("nia,ni,na->n", chart.jacobian[t], gx[idx], normal)
        other = chart.neighbours[t, k]
        has_other = other >= 0
        slope_out = np.where(
            has_other, -np.einsum("nia,ni,na->n", chart.jacobian[np.maximum(other, 0)], gx[idx], normal), np.inf
        )
        held = (slope_in >= 0) & (slope_out >= 0)
        mode[idx[held]] = ON_EDGE
        tangent[idx[held]] = unit[held]
        w = barycentric[idx[held]].copy()
        w[np.arange(len(w)), k[held]] = 0.0
        w /= w.sum(axis=1, keepdims=True)
        snapped[idx[held]] = np.einsum("nk,nkc->nc", w, uv[faces[t[held]]])
        switch = ~held & (slope_out < slope_in) & on[idx].any(axis=1)
        host[idx[switch]] = other[switch]

    # at a head vertex: test every incident triangle's cone
    idx = np.flatnonzero(free & (count >= 2))
    if len(idx):
        vertex = faces[host[idx], np.argmax(barycentric[idx], axis=1)]
        start = chart.vertex_start[vertex]
        fan = chart.vertex_start[vertex + 1] - start
        owner = np.repeat(np.arange(len(idx)), fan)
        pick = np.repeat(start, fan) + np.arange(fan.sum()) - np.repeat(np.cumsum(fan) - fan, fan)
        t = chart.vertex_triangles[pick]
        k = chart.vertex_corners[pick]
        e1 = uv[faces[t, (k + 1) % 3]] - uv[vertex[owner]]
        e2 = uv[faces[t, (k + 2) % 3]] - uv[vertex[owner]]
        g = np.einsum("pia,pi->pa", chart.jacobian[t], gx[idx[owner]])
        d1 = np.einsum("pa,pa->p", g, e1) / np.linalg.norm(e1, axis=1)
        d2 = np.einsum("pa,pa->p", g, e2) / np.linalg.norm(e2, axis=1)
        # -g inside the cone of (e1, e2): steepest descent -|g| is available there
        det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        a = (-g[:, 0] * e2[:, 1] + g[:, 1] * e2[:, 0]) / det
        b = (-e1[:, 0] * g[:, 1] + e1[:, 1] * g[:, 0]) / det
        score = np.where((a >= 0) & (b >= 0), -np.linalg.norm(g, axis=1), np.minimum(d1, d2))
        uphill = np.bincount(owner, (np.minimum(d1, d2) < 0).astype(float), minlength=len(idx)) == 0
        mode[idx[uphill]] = AT_VERTEX
        snapped[idx[uphill]] = uv[vertex[uphill]]
        order = np.lexsort((score, owner))
        best = order[np.unique(owner[order], return_index=True)[1]]
        switch = ~uphill & (on[idx].sum(axis=1) >= 2)
        host[idx[switch]] = t[best][switch]
    return host, mode, tangent, snapped


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
    Hessian of :func:`membrane_hessian` (Teran et al. 2005) and backtracks (halving, at
    most :data:`MAX_BACKTRACKS`) until the trial point keeps every vertex inside the chart,
    every scalp triangle's signed uv area of its sign in ``u_start``, and satisfies Armijo;
    hosts are located anew at every evaluation. Stops when the largest vertex step
    ``|d|`` is below ``tolerance``, the squared Newton decrement ``-g . d`` below
    :data:`DECREMENT_TOLERANCE` ``* mu * sum A_t``, or an accepted step lowered the energy
    by less than ``energy_tolerance`` of it (:data:`STAGE_ENERGY_TOLERANCE` at least for
    intermediate load stages); :attr:`RelocationReport.stop` says which.

    Kinks: ``x(u)`` is only piecewise affine, so ``E(u)`` has kinks along the head's edges
    (in uv). Where the head bends, a stretched membrane's minimiser often puts vertices
    exactly on an edge, where the gradient does not vanish and plain Newton stalls with
    ever smaller steps. Hence (an active set over the kinks): the line search lands
    exactly on the first edge a vertex would cross before halving past it; a vertex on an
    edge whose both sides go uphill is held on the edge for that iteration (its one
    unknown is the position along the edge), and one at a head vertex with no downhill
    direction is held there; the others are differentiated in their downhill side. The
    holds are re-decided every iteration, so a converged result is a stationary point of
    the piecewise-smooth energy.

    The energy minimised is Eq. 15 plus :func:`fold_barrier` (zero unless a triangle is
    compressed ten-fold in uv), which keeps triangles from folding across the head's bends.

    The fixed vertices are first set to ``u_fixed``. If that flips a triangle, the boundary
    motion is extended to the free vertices harmonically; if that flips too, the motion is
    applied in load stages (halved until a stage starts unflipped, each solved to
    convergence); ``u[fixed] == u_fixed`` unless ``max_iterations`` ran out first.

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
    began = time.perf_counter()
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

    report = RelocationReport()
    free = ~fixed
    oriented = np.where((orientation < 0)[:, None], membrane.triangles[:, [0, 2, 1]], membrane.triangles)
    rest_uv = signed_areas(u_start, oriented)
    barrier_weights = FOLD_STIFFNESS * membrane.mu * membrane.areas
    energy_scale = membrane.mu * float(membrane.areas.sum())
    laplacian = None

    def admissible(u: np.ndarray) -> float | None:
        """Energy at ``u`` if inside the chart and unflipped, else None."""
        if (chart.locate(u)[0] < 0).any():
            return None
        if (signed_areas(u, membrane.triangles) * orientation <= 0).any():
            return None
        energy = membrane_energy(membrane, chart, u) + barrier(u)[0]
        return energy if np.isfinite(energy) else None

    def barrier(u: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        return fold_barrier(oriented, u, rest_uv, barrier_weights)

    def derivatives(u: np.ndarray, F: np.ndarray, gx: np.ndarray, M: np.ndarray, exact: bool):
        """``dE/du (2n,)`` of Eq. 15 plus the fold barrier, its projected Hessian and (if
        ``exact``) its exact one, ``(2n, 2n)``, at deformation gradients ``F`` and position
        gradients ``gx`` with host Jacobians ``M``."""
        _, fold_gradient, fold_blocks = barrier(u)
        g = (np.einsum("nia,ni->na", M, gx) + fold_gradient).ravel()
        blocks = _parameter_blocks(membrane, F, M)
        projected = (_assemble_blocks(membrane.triangles, _project_psd(blocks), n)
                     + _assemble_blocks(oriented, _project_psd(fold_blocks), n))
        if not exact:
            return g, projected, None
        return g, projected, _assemble_blocks(membrane.triangles, blocks, n) + _assemble_blocks(oriented, fold_blocks, n)

    def elastic_start(u: np.ndarray, target: np.ndarray) -> np.ndarray | None:
        """One Newton step of Eq. 15 with the hairline moved to ``target`` (an inhomogeneous
        Dirichlet step): the free vertices follow the boundary motion as the linearised
        membrane does, at the current hosts."""
        host, barycentric = chart.locate(u)
        x = np.einsum("nk,nkc->nc", barycentric, chart.vertices[chart.faces[host]])
        F, gx = _position_gradients(membrane, x)
        g, H, _ = derivatives(u, F, gx, chart.jacobians(host), exact=False)
        free2, fixed2 = np.repeat(free, 2), np.repeat(fixed, 2)
        rhs = -(g[free2] + H[free2][:, fixed2] @ (target - u[fixed]).ravel())
        step = _shifted_solve(H[free2][:, free2], rhs)
        if not np.isfinite(step).all():
            return None
        extended = u.copy()
        extended[fixed] = target
        extended[free] += step.reshape(-1, 2)
        return extended

    def stage_start(u: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, float, str] | None:
        nonlocal laplacian
        pinned = u.copy()
        pinned[fixed] = target
        energy = admissible(pinned)
        if energy is not None:
            return pinned, energy, "pinned"
        extended = elastic_start(u, target)
        energy = None if extended is None else admissible(extended)
        if energy is not None:
            return extended, energy, "elastic"
        if laplacian is None:
            laplacian = graph_laplacian(membrane.triangles, n)
        # a shift keeps components without a pinned vertex (zero motion) solvable
        L_ff = (laplacian[free][:, free] + HARMONIC_SHIFT * sp.identity(int(free.sum()))).tocsc()
        motion = np.zeros((n, 2))
        motion[fixed] = target - u[fixed]
        motion[free] = spla.spsolve(L_ff, -(laplacian[free][:, fixed] @ motion[fixed])).reshape(-1, 2)
        extended = u + motion
        energy = admissible(extended)
        if energy is not None:
            return extended, energy, "harmonic"
        return None

    def linearise(u: np.ndarray, energy: float, exact: bool):
        """Snapped ``u`` and its energy, reduced gradient, projected (and exact) reduced
        Hessians, basis, hosts and the count of held vertices."""
        host, barycentric = chart.locate(u)
        x = np.einsum("nk,nkc->nc", barycentric, chart.vertices[chart.faces[host]])
        F, gx = _position_gradients(membrane, x)
        _, mode, _, snapped = _activity(chart, host, barycentric, gx, free, SNAP_BARYCENTRIC)
        if (mode != FREE).any() and not np.array_equal(snapped, u):
            snapped_energy = admissible(snapped)
            if snapped_energy is not None and snapped_energy <= energy:
                u, energy = snapped, snapped_energy
                host, barycentric = chart.locate(u)
                x = np.einsum("nk,nkc->nc", barycentric, chart.vertices[chart.faces[host]])
                F, gx = _position_gradients(membrane, x)
        host, mode, tangent, _ = _activity(chart, host, barycentric, gx, free)
        M = chart.jacobians(host)
        # basis of the unknowns: 2 per free vertex, 1 (along the edge) per edge-held one
        loose = np.flatnonzero(free & (mode == FREE))
        edged = np.flatnonzero(free & (mode == ON_EDGE))
        first = 2 * np.arange(len(loose))
        rows = np.concatenate([2 * loose, 2 * loose + 1, 2 * edged, 2 * edged + 1])
        cols = np.concatenate([first, first + 1] + [2 * len(loose) + np.arange(len(edged))] * 2)
        vals = np.concatenate([np.ones(2 * len(loose)), tangent[edged, 0], tangent[edged, 1]])
        T = sp.csr_matrix((vals, (rows, cols)), shape=(2 * n, 2 * len(loose) + len(edged)))
        g, projected, exact_hessian = derivatives(u, F, gx, M, exact)
        gr = T.T @ g
        hessians = [(T.T @ H @ T).tocsc() for H in (projected, exact_hessian) if H is not None]
        return u, energy, gr, hessians, T, host, int((free & (mode != FREE)).sum())

    def direction(u: np.ndarray, gr: np.ndarray, Hr: sp.csc_matrix, T: sp.csr_matrix, host: np.ndarray):
        """Step ``(n, 2)``, squared decrement and the first fraction at which a vertex leaves its host."""
        if Hr.shape[0] == 0:  # every free vertex held at a head vertex
            return np.zeros((n, 2)), 0.0, np.inf
        z = _shifted_solve(Hr, -gr)
        d = (T @ z).reshape(n, 2)
        weights = chart._barycentric(host, u)
        local = np.einsum("nab,nb->na", chart.uv_inverse[host], d)
        rate = np.column_stack([-local.sum(axis=1), local])
        crossing = (weights > KINK_BARYCENTRIC) & (rate < 0)
        first_kink = float(np.where(crossing, weights / np.where(crossing, -rate, 1.0), np.inf).min())
        return d, float(-gr @ z), first_kink

    def small(d: np.ndarray, decrement2: float) -> bool:
        if np.sqrt((d**2).sum(axis=1)).max() < tolerance:
            report.stop = "step"
            return True
        if decrement2 < DECREMENT_TOLERANCE * energy_scale:
            report.stop = "decrement"
            return True
        return False

    def finish(u: np.ndarray, energy: float, d: np.ndarray) -> tuple[np.ndarray, float]:
        """Take the last step when it is not below the tolerance: the decrement stopped the
        loop because Armijo can no longer be told from round-off; keep the step if it is
        admissible and does not raise the energy."""
        if np.sqrt((d**2).sum(axis=1)).max() < tolerance:
            return u, energy
        trial_energy = admissible(u + d)
        if trial_energy is None or trial_energy > energy:
            return u, energy
        report.iterations += 1
        report.energy.append(trial_energy)
        report.step_sizes.append(1.0)
        return u + d, trial_energy

    u = u_start.copy()
    base = u_start[fixed]
    reached = 0.0
    converged = False
    while True:
        fraction = 1.0
        while True:
            target = u_fixed if fraction == 1.0 else base + fraction * (u_fixed - base)
            started = stage_start(u, target)
            if started is not None:
                break
            fraction = 0.5 * (reached + fraction)
            if fraction - reached < MIN_LOAD_FRACTION:
                raise InputError(
                    f"the hairline edit is too drastic for this scalp: beyond {100 * reached:.0f} % of the "
                    "hairline's motion the scalp would fold over itself on the head; use a smaller amount "
                    "or a curve closer to the current hairline", "relocate", "hairline_too_far")
        u, energy, how = started
        reached = fraction
        report.stages += 1
        report.start.append(how)
        report.energy.append(energy)
        converged = not free.any()
        full_step = False
        stall = energy_tolerance if reached >= 1.0 else max(energy_tolerance, STAGE_ENERGY_TOLERANCE)
        report.stop = "step" if converged else "iterations"

        def stalled(before: float, after: float) -> bool:
            return before - after <= stall * abs(before)

        while not converged and report.iterations < max_iterations:
            exact = polish and full_step
            u, energy, gr, hessians, T, host, held = linearise(u, energy, exact)
            report.held.append(held)
            if exact:
                # the exact Hessian's full step, taken only if it is an admissible Armijo descent
                d, decrement2, _ = direction(u, gr, hessians[1], T, host)
                if decrement2 > 0:
                    if small(d, decrement2):
                        u, energy = finish(u, energy, d)
                        converged = True
                        break
                    trial_energy = admissible(u + d)
                    if trial_energy is not None and trial_energy <= energy - ARMIJO * decrement2:
                        converged = stalled(energy, trial_energy)
                        u, energy = u + d, trial_energy
                        report.iterations += 1
                        report.energy.append(energy)
                        report.step_sizes.append(1.0)
                        report.exact_steps += 1
                        if converged:
                            report.stop = "energy"
                        continue
            d, decrement2, first_kink = direction(u, gr, hessians[0], T, host)
            if small(d, decrement2):
                u, energy = finish(u, energy, d)
                converged = True
                break
            alpha = 1.0
            accepted = None
            for _ in range(MAX_BACKTRACKS + 1):
                trial = u + alpha * d
                trial_energy = admissible(trial)
                if trial_energy is not None and trial_energy <= energy - ARMIJO * alpha * decrement2:
                    accepted = trial
                    break
                # land on the first kink rather than halving past it
                alpha = first_kink if 0.5 * alpha <= first_kink < alpha else 0.5 * alpha
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
            report.iterations += 1
            report.energy.append(energy)
            report.step_sizes.append(alpha)
        if reached >= 1.0 or report.iterations >= max_iterations:
            break
    report.converged = converged and reached >= 1.0
    report.seconds = time.perf_counter() - began
    return u, report
