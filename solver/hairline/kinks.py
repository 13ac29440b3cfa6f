"""Kinks of the membrane energy on the piecewise-linear head (Eq. 18-19): the active set of
:func:`.newton.relocate`.

Inside a head triangle a scalp vertex's position ``x(u)`` is affine in its parameters, so the
energy of Eq. 15 is smooth there; across a head edge the Jacobian jumps and ``E(u)`` has a
kink. Where the head bends, a stretched membrane's minimiser often puts vertices exactly on an
edge, where the gradient does not vanish and plain Newton stalls with ever smaller steps.
Hence an active set over the kinks (:func:`kink_activity`): a vertex on an edge whose both
sides go uphill is held on the edge for that iteration (its one unknown is the position along
the edge), and one at a head vertex with no downhill direction is held there; the others are
differentiated in their downhill side. The holds are re-decided every iteration, so a
converged result is a stationary point of the piecewise-smooth energy.
"""

from __future__ import annotations

import numpy as np

from hairport.solver.hairline.head_chart import HeadChart
from hairport.solver.mesh.triangles import interpolate_barycentric

#: a scalp vertex whose barycentric coordinate in its host is below this lies on the
#: host's edge (one small coordinate) or vertex (two): where the piecewise-linear head
#: bends, the energy has a kink there (see :func:`.newton.relocate`)
KINK_BARYCENTRIC = 1e-10
#: a free vertex this close (barycentric) to a head edge or vertex where both sides go
#: uphill is moved onto it when that lowers the energy (Newton would otherwise approach
#: the kink by ever shorter steps)
SNAP_BARYCENTRIC = 1e-6
#: a vertex's activity: free in its host (2 unknowns), held on a head edge (1) or at a
#: head vertex (0)
FREE, ON_EDGE, AT_VERTEX = 0, 1, 2


def kink_activity(
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
    snapped = interpolate_barycentric(uv, faces, host, barycentric)
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
        snapped[idx[held]] = interpolate_barycentric(uv, faces, t[held], w)
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
