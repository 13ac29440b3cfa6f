"""A barrier against folding the scalp over the head, in the parameterization (added to Eq. 15).

Eq. 15's ``J`` measures a deformed triangle's 3D area, which a triangle folded across a bend of
the piecewise-flat head keeps: near a fold the membrane feels little resistance. The barrier
acts on each scalp triangle's signed area in uv instead, and is exactly zero until a triangle
is compressed ten-fold there, so away from folds the minimiser is Eq. 15's.
"""

from __future__ import annotations

import numpy as np

from hairport.solver.mesh.areas import signed_areas

#: a scalp triangle whose uv area falls below this share of its starting one meets the barrier
FOLD_THRESHOLD = 0.1
#: weight of the fold barrier per triangle, in units of ``mu * A_t``: the barrier only grows
#: like a logarithm, and at 1 a triangle folded to 1e-4 of its uv area costs less than
#: the same triangle compressed three-fold in 3D
FOLD_STIFFNESS = 1000.0


#: d(2 * signed uv area) / d u as a constant (6, 6) Hessian over a triangle's corner
#: parameters (vertex-major): twice the area is ``(u1 - u0) x (u2 - u0)``
_AREA_HESSIAN = np.zeros((6, 6))
for _k in range(3):
    _AREA_HESSIAN[2 * _k, 2 * ((_k + 1) % 3) + 1] = 1.0  # d/du_{k,x} of (u_{k+1,y} - u_{k+2,y})
    _AREA_HESSIAN[2 * _k, 2 * ((_k + 2) % 3) + 1] = -1.0
    _AREA_HESSIAN[2 * _k + 1, 2 * ((_k + 2) % 3)] = 1.0  # d/du_{k,y} of (u_{k+2,x} - u_{k+1,x})
    _AREA_HESSIAN[2 * _k + 1, 2 * ((_k + 1) % 3)] = -1.0
_AREA_HESSIAN *= 0.5


def fold_barrier(
    triangles: np.ndarray, u: np.ndarray, rest_uv_areas: np.ndarray, weights: np.ndarray,
    threshold: float = FOLD_THRESHOLD,
) -> tuple[float, np.ndarray, np.ndarray]:
    """A barrier against folding the scalp over the head, in the parameterization.

    Eq. 15's ``J`` measures a deformed triangle's 3D area, which a triangle folded across a
    bend of the piecewise-flat head keeps (its corners are not collinear in 3D even where
    they are in uv): near a fold the membrane feels little resistance. Each triangle whose
    uv area ratio ``r = a / a_0`` to its starting one is below ``r^ = threshold`` adds
    ``w_t b(r)`` with the C2 log barrier ``b(r) = -(r - r^)^2 ln(r / r^)`` (zero with its
    first two derivatives at ``r^``, infinite at 0). Above the threshold, i.e. away from
    ten-fold compressions, it is exactly zero and the result is Eq. 15's.

    Parameters
    ----------
    triangles : (m, 3) int64
    u : (n, 2) float64
    rest_uv_areas : (m,) float64
        Positive signed uv areas at the start.
    weights : (m,) float64
        ``w_t`` (J), e.g. ``mu * A_t``.
    threshold : float

    Returns
    -------
    energy : float
        ``+inf`` if a triangle has ``r <= 0``.
    gradient : (n, 2) float64
    blocks : (m, 6, 6) float64
        Per-triangle Hessians over the corners' parameters (zero where inactive).
    """
    n, m = len(u), len(triangles)
    ratio = signed_areas(u, triangles) / rest_uv_areas
    gradient = np.zeros((n, 2))
    blocks = np.zeros((m, 6, 6))
    active = np.flatnonzero(ratio < threshold)
    if len(active) == 0:
        return 0.0, gradient, blocks
    r = ratio[active]
    if (r <= 0).any():
        return np.inf, gradient, blocks
    log = np.log(r / threshold)
    gap = r - threshold
    energy = float(np.sum(weights[active] * -(gap**2) * log))
    db = -2.0 * gap * log - gap**2 / r
    d2b = -2.0 * log - 4.0 * gap / r + gap**2 / r**2
    U = u[triangles[active]]  # (a, 3, 2)
    nxt, prv = U[:, [1, 2, 0]], U[:, [2, 0, 1]]
    # d(signed area)/du_k = 0.5 (u_{k+1,y} - u_{k+2,y}, u_{k+2,x} - u_{k+1,x})
    d_area = 0.5 * np.stack([nxt[..., 1] - prv[..., 1], prv[..., 0] - nxt[..., 0]], axis=2).reshape(-1, 6)
    d_ratio = d_area / rest_uv_areas[active, None]
    w = weights[active]
    per_corner = ((w * db)[:, None] * d_ratio).reshape(-1, 3, 2)
    for c in range(2):
        gradient[:, c] = np.bincount(triangles[active].ravel(), per_corner[..., c].ravel(), minlength=n)
    blocks[active] = (w * d2b)[:, None, None] * d_ratio[:, :, None] * d_ratio[:, None, :] + (
        (w * db) / rest_uv_areas[active])[:, None, None] * _AREA_HESSIAN[None]
    return energy, gradient, blocks

