"""Disk parameterisations of a triangle patch (harmonic, LSCM, ARAP through libigl) with injectivity checks."""

from __future__ import annotations

import igl
import numpy as np

from hairport.solver.mesh.areas import signed_areas
from hairport.solver.mesh.topology import check_disk
from hairport.solver.model.errors import InputError

PARAMETERIZATIONS = ("harmonic", "lscm", "arap")


#: local-global iterations of the ARAP parameterization
ARAP_ITERATIONS = 50
#: a parameterized triangle is flipped or degenerate when its signed area is below this
#: fraction of the mean triangle area in uv
MIN_UV_AREA_FRACTION = 1e-12


def check_parameterization(method: str) -> None:
    """Refuse a method not in :data:`PARAMETERIZATIONS` (code ``bad_option``)."""
    if method not in PARAMETERIZATIONS:
        raise InputError(f"unknown parameterization {method!r}; expected one of {', '.join(PARAMETERIZATIONS)}",
                         code="bad_option")


def _segments_cross(polygon: np.ndarray) -> bool:
    """Whether two non-adjacent edges of a closed polygon ``(b, 2)`` intersect."""
    b = len(polygon)
    if b < 4:
        return False
    p, q = polygon, np.roll(polygon, -1, axis=0)
    i, j = np.triu_indices(b, k=2)
    keep = ~((i == 0) & (j == b - 1))
    i, j = i[keep], j[keep]

    def orient(a, c, d):
        return (c[:, 0] - a[:, 0]) * (d[:, 1] - a[:, 1]) - (c[:, 1] - a[:, 1]) * (d[:, 0] - a[:, 0])

    d1 = orient(p[i], q[i], p[j])
    d2 = orient(p[i], q[i], q[j])
    d3 = orient(p[j], q[j], p[i])
    d4 = orient(p[j], q[j], q[i])
    return bool(np.any((d1 * d2 <= 0) & (d3 * d4 <= 0)))


def check_injective(uv: np.ndarray, triangles: np.ndarray, boundary: np.ndarray, method: str = "") -> None:
    """Raise :class:`InputError` unless ``uv (p, 2)`` maps the disk ``triangles (q, 3)`` with
    boundary loop ``boundary (b,)`` one to one (no flipped or degenerate triangle, simple
    boundary polygon)."""
    area = signed_areas(uv, triangles)
    tolerance = MIN_UV_AREA_FRACTION * abs(float(np.mean(area)))
    bad = int(np.sum(area <= tolerance))
    label = f"{method} " if method else ""
    if not np.isfinite(uv).all():
        raise InputError(f"the {label}parameterization has non-finite coordinates", code="not_injective")
    if bad:
        raise InputError(
            f"the {label}parameterization flips or collapses {bad} of {len(triangles)} triangles",
            code="not_injective",
        )
    if _segments_cross(uv[boundary]):
        raise InputError(f"the {label}parameterization's boundary crosses itself", code="not_injective")


def _fit_unit_disk(uv: np.ndarray) -> np.ndarray:
    centre = 0.5 * (uv.min(axis=0) + uv.max(axis=0))
    uv = uv - centre
    return uv / np.sqrt(np.max(np.einsum("ij,ij->i", uv, uv)))


def _harmonic(vertices: np.ndarray, triangles: np.ndarray, boundary: np.ndarray) -> np.ndarray:
    circle = igl.map_vertices_to_circle(np.asfortranarray(vertices), boundary.astype(np.int32))
    return igl.harmonic(vertices, triangles, boundary, np.ascontiguousarray(circle), 1)


def parameterize(vertices: np.ndarray, triangles: np.ndarray, method: str = "harmonic") -> np.ndarray:
    """A one-to-one map of a disk-shaped patch into the unit disk.

    Parameters
    ----------
    vertices : (p, 3) float64
        Every vertex used by ``triangles``.
    triangles : (q, 3) int64
        A topological disk, consistently oriented.
    method : str
        One of :data:`PARAMETERIZATIONS` (see the module docstring).

    Returns
    -------
    uv : (p, 2) float64
        Inside the unit disk (``harmonic``: the boundary on the unit circle, its loop
        counter-clockwise), every triangle counter-clockwise (positive signed area).

    Raises
    ------
    InputError
        Unknown method, bad shapes, unused vertices, a patch that is not a disk, or a map
        that is not injective.
    """
    check_parameterization(method)
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    triangles = np.ascontiguousarray(triangles, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or triangles.ndim != 2 or triangles.shape[1] != 3:
        raise InputError(f"expected vertices (p, 3) and triangles (q, 3), got {vertices.shape} and {triangles.shape}",
                         code="bad_mesh")
    if len(triangles) == 0:
        raise InputError("the patch has no triangles", code="not_a_disk")
    if triangles.min() < 0 or triangles.max() >= len(vertices):
        raise InputError("triangle vertex id out of range", code="bad_mesh")
    if len(np.unique(triangles)) != len(vertices):
        raise InputError("the patch has vertices used by no triangle", code="bad_mesh")
    boundary = check_disk(triangles, "patch")
    if method == "harmonic":
        uv = _harmonic(vertices, triangles, boundary)
    elif method == "lscm":
        first = boundary[0]
        far = boundary[np.argmax(np.linalg.norm(vertices[boundary] - vertices[first], axis=1))]
        pins = np.array([first, far], dtype=np.int64)
        uv, _ = igl.lscm(vertices, triangles, pins, np.array([[0.0, 0.0], [1.0, 0.0]]))
    else:
        # the harmonic map scaled to the surface's area, one boundary vertex pinned where it
        # starts (without a pin the global step's Laplacian is singular)
        start = _harmonic(vertices, triangles, boundary)
        area_3d = 0.5 * float(np.sum(igl.doublearea(vertices, triangles)))
        start *= np.sqrt(area_3d / abs(float(np.sum(signed_areas(start, triangles)))))
        pin = boundary[:1].astype(np.int32)
        data = igl.ARAPData()
        data.max_iter = ARAP_ITERATIONS
        igl.arap_precomputation(vertices, triangles, 2, pin, data)
        uv = igl.arap_solve(np.ascontiguousarray(start[pin]), data, start)
    uv = np.ascontiguousarray(uv, dtype=np.float64)
    if np.sum(signed_areas(uv, triangles)) < 0:  # a mirror image: flip it
        uv[:, 1] = -uv[:, 1]
    check_injective(uv, triangles, boundary, method)
    if method != "harmonic":
        uv = _fit_unit_disk(uv)
    return uv
