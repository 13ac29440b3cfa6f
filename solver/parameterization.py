"""A 2D parameterization of the head around the scalp (the space of Eq. 18-19, Section 6.1).

Convention: a patch is ``vertices (p, 3) float64`` (meters) and ``triangles (q, 3) int64``
in local numbering, counter-clockwise seen from outside, forming a topological disk; its
parameterization is ``uv (p, 2) float64`` inside the unit disk, with every triangle
counter-clockwise in the plane (positive signed area).

The paper parameterizes the head surface with a harmonic map [38] and notes that the
membrane's result hardly depends on that choice (Figure 17); :data:`PARAMETERIZATIONS`
offers three, all libigl:

``harmonic``
    The boundary loop on the unit circle by arc length (``igl.map_vertices_to_circle``),
    the interior by the cotangent Laplace equation (``igl.harmonic``, ``k = 1``). Tutte's
    theorem makes it injective for positive weights; obtuse triangles can make cotangent
    weights negative, hence the check below.
``lscm``
    Least-squares conformal map (``igl.lscm``) with the first boundary vertex and the
    boundary vertex farthest from it (3D) pinned; free boundary.
``arap``
    As-rigid-as-possible (``igl.arap_precomputation`` + ``igl.arap_solve``, 2D) from the
    harmonic map scaled to the patch's area, ``ARAP_ITERATIONS`` local-global iterations;
    free boundary, the first boundary vertex pinned (translation only: with no pinned vertex
    libigl's factorisation of the singular Laplacian fails on some patches).

Every result is checked: every triangle has a positive signed area larger than
``MIN_UV_AREA_FRACTION`` of the mean, and the boundary polygon does not cross itself (a
locally injective map of a disk whose boundary is a simple polygon is injective);
otherwise :class:`InputError`. The free-boundary methods are then moved and scaled to fit
the unit disk (centre of the bounding box at the origin, farthest vertex at radius 1); the
harmonic map already has its boundary on the unit circle and is left as it is.

The patch (:func:`head_patch`): the scalp grown by ``margin_rings`` rings of head faces,
so that a hairline moved outward still lies inside the parameterized region.
"""

from __future__ import annotations

import igl
import numpy as np

from .character import Character
from .errors import InputError
from .groom import HeadFrame, head_frame
from .scalp import Scalp, check_disk, face_adjacency, make_disk, submesh

PARAMETERIZATIONS = ("harmonic", "lscm", "arap")
#: rings of head faces (vertex-neighbour rings) added around the scalp; 1-3 cm each on
#: the MakeHuman head
DEFAULT_MARGIN_RINGS = 6
#: local-global iterations of the ARAP parameterization
ARAP_ITERATIONS = 50
#: a parameterized triangle is flipped or degenerate when its signed area is below this
#: fraction of the mean triangle area in uv
MIN_UV_AREA_FRACTION = 1e-12


def head_patch(
    character: Character,
    scalp: Scalp,
    margin_rings: int = DEFAULT_MARGIN_RINGS,
    frame: HeadFrame | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A disk-shaped patch of the head around the scalp.

    The scalp's faces, grown ``margin_rings`` times by every head face (three head-dominant
    vertices, :attr:`.groom.HeadFrame.head_vertices`) sharing a vertex with the patch, then
    made a disk (holes filled, pinch vertices repaired; :func:`.scalp.make_disk`).

    Parameters
    ----------
    character : Character
    scalp : Scalp
        From :func:`.scalp.extract_scalp` on this character.
    margin_rings : int
        >= 0; 0 gives the scalp itself.
    frame : HeadFrame, optional
        Reuse a frame from :func:`.groom.head_frame`.

    Returns
    -------
    vertices : (p,) int64
        Ascending ids of the character's vertices in the patch.
    triangles : (q, 3) int64
        The patch's faces in local numbering (into ``vertices``).
    faces : (q,) int64
        Ascending ids of the character's faces, row for row with ``triangles``.

    Raises
    ------
    InputError
        Negative ``margin_rings``, or a patch that cannot be made a disk.
    """
    if margin_rings < 0:
        raise InputError("margin_rings must be >= 0", code="bad_option")
    frame = frame or head_frame(character)
    faces = character.faces
    head_faces = frame.head_vertices[faces].all(axis=1)
    region = np.zeros(len(faces), dtype=bool)
    region[scalp.faces] = True
    for _ in range(margin_rings):
        touched = np.zeros(character.n_vertices, dtype=bool)
        touched[faces[region].ravel()] = True
        region |= head_faces & touched[faces].any(axis=1)
    weight = np.zeros(len(faces))
    weight[scalp.faces] = 1.0
    disk = make_disk(faces, region, face_adjacency(faces), weight, "head patch")
    face_ids = np.flatnonzero(disk).astype(np.int64)
    vertices, triangles = submesh(faces, face_ids)
    return vertices, triangles, face_ids


def signed_areas(uv: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(q,) signed areas of ``triangles (q, 3)`` in ``uv (p, 2)``, positive counter-clockwise."""
    a, b, c = uv[triangles[:, 0]], uv[triangles[:, 1]], uv[triangles[:, 2]]
    e1, e2 = b - a, c - a
    return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


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
    if method not in PARAMETERIZATIONS:
        raise InputError(f"unknown parameterization {method!r}; expected one of {', '.join(PARAMETERIZATIONS)}",
                         code="bad_option")
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
