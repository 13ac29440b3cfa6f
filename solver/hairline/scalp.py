"""The scalp of a hairstyle on a character and its hairline (paper Section 6.1).

Convention: a character's ``vertices (V, 3) float64`` in meters and ``faces (F, 3) int64``
counter-clockwise seen from outside; a :class:`Scalp` names the character's faces and
vertices it uses (ids into the character) and stores its triangles in a local numbering
(ids into ``Scalp.vertices``), so its positions are ``character.vertices[scalp.vertices]``
and its sub-mesh is ``(character.vertices[scalp.vertices], scalp.triangles)``.

Scalp (:func:`extract_scalp`)
-----------------------------
The paper collects "all the head mesh triangles with at least one root particle inside".
That set is a clean region only when the roots cover every triangle, as the paper's dense
hairstyles do. A groom of a few hundred strands on the MakeHuman head (518 scalp faces)
hits 211 faces in 72 edge-connected pieces, so the root faces are first *closed*: on the
vertices of the root faces, a graph dilation by ``r`` rings followed by an erosion by ``r``
rings (the closing always contains the starting set), then every face whose three vertices
are in the closed set. ``r`` is the smallest of ``0 .. MAX_CLOSING_RINGS`` for which one
edge-connected piece holds every root (``r = 0`` is the paper's set as it is), or, when
none does, the smallest for which the piece holding the most roots holds most.

All of this happens on the *skin shell* that carries the roots
(:func:`~hairport.solver.mesh.shells.root_shell`): real character meshes also carry eyes,
teeth and lashes as separate pieces, fins on non-manifold edges and open borders; those
pieces take no part, and roots on them are strays. Roots spread over several pieces (less
than 90 % on one) are refused (``roots_on_several_pieces``).

The piece holding the most roots is kept (roots outside it are *strays*: kept in
:attr:`Scalp.strays` and reported with a :class:`ScalpWarning`); its holes, the pieces of
the rest of the skin that do not hold the rest of the body, are filled. On a closed genus-0
body (MakeHuman) an edge-connected region whose complement is edge-connected is a disk;
elsewhere the faces around pinch vertices are added, and a region that is still not a disk
is refused (:class:`InputError`) saying why (:func:`check_region_disk`): a gap in the mesh
inside it (``mesh_hole``), non-manifold edges inside it (``not_manifold``), or else
``not_a_disk``.

Hairline
--------
The boundary loop of the scalp, oriented by the triangles (the scalp on the left, seen from
outside): counter-clockwise seen from above the head. It is split at the ears, found from
the head frame (:func:`~hairport.solver.body.head_frame.head_frame`), not from vertex ids: the ears are where the loop
crosses the coronal plane ``(p - origin) . forward = EAR_PLANE_FORWARD_M`` farthest to the
left and to the right. The part between them in front is :attr:`Scalp.front`, the rest
:attr:`Scalp.back`; the loop starts with the front part, which runs from the character's
right ear to its left ear.

Turning points (:func:`turning_points`) are corners of the front part seen from the front
(projected on the ``(side, up)`` plane, lightly smoothed): vertices where the direction
changes by more than ``TURNING_ANGLE_DEG`` over ``TURNING_WINDOW_M`` either side (local
maxima only), plus both ends.

Refinement (:func:`refine_scalp`)
---------------------------------
A finer copy for the membrane of Eq. 15: 1-to-4 midpoint subdivision, which stays on the
head exactly (every new edge lies in one head triangle).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from hairport.solver.body.head_frame import REFERENCE_CROWN_M, HeadFrame, head_frame
from hairport.solver.mesh.polyline import polyline_arc_length
from hairport.solver.mesh.shells import explain_not_disk, root_shell
from hairport.solver.mesh.topology import (
    boundary_edges,
    boundary_loops,
    check_disk,
    euler_characteristic,
    face_adjacency,
    largest_piece,
    repair_disk,
    subdivide,
    submesh,
    vertex_adjacency,
)
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError

#: fewest root faces that can make a scalp
MIN_SCALP_FACES = 3
#: largest closing radius (vertex rings) tried to join scattered root faces into one piece
MAX_CLOSING_RINGS = 4


#: forward coordinate (m, from the head joint along HeadFrame.forward) of the coronal plane
#: through the ears; the most lateral points of the MakeHuman ears lie 0.2-1 cm behind the
#: head joint in every preset
EAR_PLANE_FORWARD_M = 0.0
#: umbrella smoothing passes (weights 1/4, 1/2, 1/4, ends fixed) over the projected front
#: hairline before turning angles are measured
HAIRLINE_SMOOTHING_ITERATIONS = 3
#: half-width (m of projected arc length, for a head of crown height REFERENCE_CROWN_M;
#: scales with the head) of the chords that measure the turning angle
TURNING_WINDOW_M = 0.012
#: a front hairline vertex is a turning point when its turning angle exceeds this (degrees)
TURNING_ANGLE_DEG = 40.0
#: the membrane's default resolution: refine until the scalp has at least this many triangles
#: (one round, ~8 mm edges, for MakeHuman scalps of 250-1000 faces: a membrane vertex
#: every half head edge; a second round (~4 mm) gives the same roots to ~0.3 mm at about
#: five times the relocation time)
DEFAULT_MIN_TRIANGLES = 1000


class ScalpWarning(UserWarning):
    """Roots that were left out of the scalp (strays)."""


@dataclass(frozen=True, eq=False)
class Scalp:
    """The faces holding hair roots, made a disk, and its hairline.

    Attributes
    ----------
    faces : (k,) int64
        Ids of the character's faces forming the scalp (a topological disk), ascending.
    vertices : (n,) int64
        Ids of the character's vertices used by them, ascending.
    triangles : (k, 3) int64
        ``faces`` in local vertex numbering (into ``vertices``), same order and orientation.
    boundary : (b,) int64
        Local vertex ids of the hairline loop, ordered, counter-clockwise seen from above
        the head (the scalp on the left); starts with ``front``.
    front : (f,) int64
        The front part of the hairline, ``boundary[:f]``: from the character's right ear to
        its left ear.
    back : (b - f,) int64
        The rest of the loop, ``boundary[f:]``.
    turning_points : (t,) int64
        Ascending indices into ``front`` of its corners, always including ``0`` and ``f - 1``.
    closing_rings : int
        Closing radius (vertex rings) used to join the root faces (0: the root faces as they are).
    strays : (m,) int64
        Root faces (unique character face ids) left outside the scalp.
    """

    faces: np.ndarray
    vertices: np.ndarray
    triangles: np.ndarray
    boundary: np.ndarray
    front: np.ndarray
    back: np.ndarray
    turning_points: np.ndarray
    closing_rings: int = 0
    strays: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    @property
    def n_faces(self) -> int:
        return len(self.faces)

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)


def _closed_faces(faces: np.ndarray, seed_vertices: np.ndarray, rings: int, vadj: sp.csr_matrix) -> np.ndarray:
    """(F,) bool: faces with all three vertices in the ``rings``-ring graph closing of
    ``seed_vertices (V,) bool``."""
    grown = seed_vertices.copy()
    for _ in range(rings):
        grown = grown | (vadj @ grown)
    for _ in range(rings):
        grown = grown & ~(vadj @ ~grown)
    return grown[faces].all(axis=1)


def _rotate_to(loop: np.ndarray, start: int) -> np.ndarray:
    return np.roll(loop, -start)


def split_hairline(points: np.ndarray, frame: HeadFrame) -> tuple[int, int]:
    """Where an ordered hairline loop is split at the ears.

    Parameters
    ----------
    points : (b, 3) float64
        The loop's positions, in loop order (counter-clockwise seen from above).
    frame : HeadFrame

    Returns
    -------
    start, count : int
        The front part is ``count`` vertices from loop index ``start`` (cyclically).

    Raises
    ------
    InputError
        The loop does not cross the ear plane on both sides of the head.
    """
    local = frame.local(points)
    depth = local[:, 1] - EAR_PLANE_FORWARD_M
    side = local[:, 2]
    b = len(points)
    nxt = np.roll(np.arange(b), -1)
    ahead = depth >= 0.0
    crossing = np.flatnonzero(ahead != ahead[nxt])  # edge i -> i+1 crosses the plane
    if len(crossing) < 2:
        raise InputError(
            "the hairline does not cross the ear plane (coronal plane through the head joint) on both "
            "sides: the roots do not cover a scalp around the head",
            code="bad_scalp",
        )
    d0, d1 = depth[crossing], depth[nxt[crossing]]
    t = d0 / (d0 - d1)
    cross_side = side[crossing] + t * (side[nxt[crossing]] - side[crossing])
    left, right = cross_side > 0.0, cross_side < 0.0
    if not left.any() or not right.any():
        raise InputError(
            "the hairline crosses the ear plane on one side of the head only: the scalp does not "
            "reach both ears",
            code="bad_scalp",
        )
    e_left = crossing[left][np.argmax(cross_side[left])]
    e_right = crossing[right][np.argmin(cross_side[right])]
    # the two arcs between the crossings: after e_right up to e_left, after e_left up to e_right
    arcs = []
    for first, last in ((e_right, e_left), (e_left, e_right)):
        start = (first + 1) % b
        count = (last - first) % b
        arcs.append((start, count))
    means = [np.mean(depth[(s + np.arange(c)) % b]) if c else -np.inf for s, c in arcs]
    start, count = arcs[int(np.argmax(means))]
    if count < 2 or count >= b:
        raise InputError("the front hairline between the ears has fewer than 2 vertices", code="bad_scalp")
    return int(start), int(count)


def turning_points(points: np.ndarray, frame: HeadFrame) -> np.ndarray:
    """Corners of the front hairline seen from the front.

    Parameters
    ----------
    points : (f, 3) float64
        The front hairline in order.
    frame : HeadFrame

    Returns
    -------
    corners : (t,) int64
        Ascending indices into ``points``: both ends and every local maximum of the turning
        angle above ``TURNING_ANGLE_DEG`` at least a window away from the ends.
    """
    f = len(points)
    ends = np.array([0, f - 1], dtype=np.int64) if f > 1 else np.zeros(1, np.int64)
    if f < 3:
        return ends
    local = frame.local(points)
    xy = local[:, [2, 0]]  # front view: (side, up)
    for _ in range(HAIRLINE_SMOOTHING_ITERATIONS):
        xy[1:-1] = 0.25 * xy[:-2] + 0.5 * xy[1:-1] + 0.25 * xy[2:]
    arc = polyline_arc_length(xy)
    window = TURNING_WINDOW_M * frame.crown / REFERENCE_CROWN_M
    if arc[-1] <= 2.0 * window:
        return ends
    behind = np.stack([np.interp(arc - window, arc, xy[:, k]) for k in range(2)], axis=1)
    ahead = np.stack([np.interp(arc + window, arc, xy[:, k]) for k in range(2)], axis=1)
    incoming, outgoing = xy - behind, ahead - xy
    cross = incoming[:, 0] * outgoing[:, 1] - incoming[:, 1] * outgoing[:, 0]
    angle = np.degrees(np.abs(np.arctan2(cross, np.einsum("ij,ij->i", incoming, outgoing))))
    interior = (arc > window) & (arc < arc[-1] - window)
    # local maxima: no vertex within the window has a larger angle (ties: the first)
    near = np.abs(arc[:, None] - arc[None, :]) <= window
    order = np.arange(f)
    tie = (angle[None, :] == angle[:, None]) & (order[None, :] < order[:, None])
    larger = (angle[None, :] > angle[:, None]) | tie
    peak = ~(near & larger).any(axis=1)
    corners = np.flatnonzero(interior & peak & (angle > TURNING_ANGLE_DEG))
    return np.unique(np.concatenate([ends, corners])).astype(np.int64)


def check_region_disk(character: Character, region: np.ndarray, shell: np.ndarray, what: str) -> None:
    """Refuse a region ``(F,) bool`` of the character's ``shell (F,) bool`` that is not a disk,
    saying why in the user's terms (:func:`~hairport.solver.mesh.shells.explain_not_disk`:
    ``mesh_hole``, ``not_manifold``; else ``not_a_disk``)."""
    triangles = submesh(character.faces, np.flatnonzero(region))[1]
    try:
        check_disk(triangles, what)
    except InputError as error:
        explained = explain_not_disk(character.faces, region, shell, what, character.vertices, character.name)
        if explained is not None:
            raise explained from error
        raise InputError(f"the roots do not make one disk-shaped {what}: {_disk_defect(triangles, what)}",
                         character.name, "not_a_disk") from error


def _disk_defect(triangles: np.ndarray, what: str) -> str:
    """What keeps a region ``(k, 3)`` from being a disk, in words."""
    try:
        loops = len(boundary_loops(triangles))
    except InputError:
        return "its border touches itself at a vertex"
    handles = (2 - euler_characteristic(triangles) - loops) // 2
    if loops == 0:
        return f"the {what} would cover a whole closed piece of the mesh, leaving no hairline"
    if handles > 0:
        return f"the {what} wraps around {handles} tunnel(s) through the mesh"
    return f"its border has {loops} loops (the roots surround {loops - 1} piece(s) of the mesh they leave bare)"


def extract_scalp(character: Character, root_faces: np.ndarray, frame: HeadFrame | None = None) -> Scalp:
    """The scalp of a hairstyle: the faces holding its roots, made a disk, and its hairline.

    Parameters
    ----------
    character : Character
        Its head frame finds the ears (:func:`~hairport.solver.body.head_frame.head_frame`: from a ``head``
        bone, or from the mesh without a rig).
    root_faces : (S,) int64
        The face holding each root (duplicates count as more roots; e.g.
        ``adaptable.anchors.face[adaptable.hair.roots]``).
    frame : HeadFrame, optional
        Reuse a frame from :func:`~hairport.solver.body.head_frame.head_frame`.

    Returns
    -------
    scalp : Scalp

    Raises
    ------
    InputError
        Fewer than ``MIN_SCALP_FACES`` distinct root faces, face ids out of range, roots on
        several pieces of the mesh, a region that cannot be made a disk, or a hairline that
        does not reach both ears.
    """
    faces = character.faces
    root_faces = np.asarray(root_faces).ravel()
    if root_faces.size and not np.issubdtype(root_faces.dtype, np.integer):
        raise InputError("root faces must be integer face ids", character.name, "bad_scalp")
    root_faces = root_faces.astype(np.int64)
    if root_faces.size and (root_faces.min() < 0 or root_faces.max() >= len(faces)):
        raise InputError(f"root face ids must lie in [0, {len(faces)})", character.name, "bad_scalp")
    unique_roots = np.unique(root_faces)
    if len(unique_roots) < MIN_SCALP_FACES:
        raise InputError(
            f"the roots lie on {len(unique_roots)} faces; a scalp needs at least {MIN_SCALP_FACES}",
            character.name,
            "bad_scalp",
        )
    frame = frame or head_frame(character)
    # the skin shell carrying the roots; other shells (eyes, teeth, lashes, fins on
    # non-manifold edges) take no part, and roots on them are strays
    shell = root_shell(faces, root_faces, character.name)
    shell_faces = np.flatnonzero(shell)
    skin = faces[shell_faces]
    local = np.full(len(faces), -1, dtype=np.int64)
    local[shell_faces] = np.arange(len(shell_faces))
    adjacency = face_adjacency(skin)
    vadj = vertex_adjacency(skin, character.n_vertices)
    on_skin = local[root_faces] >= 0
    roots_per_face = np.bincount(local[root_faces[on_skin]], minlength=len(skin)).astype(np.float64)
    seed_faces = roots_per_face > 0
    seed_vertices = np.zeros(character.n_vertices, dtype=bool)
    seed_vertices[skin[seed_faces].ravel()] = True
    best = (-1.0, 0, None)  # roots held, rings, piece
    for rings in range(MAX_CLOSING_RINGS + 1):
        region = seed_faces if rings == 0 else _closed_faces(skin, seed_vertices, rings, vadj)
        piece = largest_piece(region, adjacency, roots_per_face)
        held = float(roots_per_face[piece].sum())
        if held > best[0]:
            best = (held, rings, piece)
        if held == on_skin.sum():
            break
    _, rings, piece = best
    disk = np.zeros(len(faces), dtype=bool)
    disk[shell_faces[repair_disk(skin, piece, adjacency, roots_per_face, "scalp")]] = True
    check_region_disk(character, disk, shell, "scalp")
    strays = unique_roots[~disk[unique_roots]]
    if len(strays):
        warnings.warn(
            f"{character.name}: {int(np.isin(root_faces, strays).sum())} roots on {len(strays)} faces lie "
            "outside the scalp and were left out",
            ScalpWarning,
            stacklevel=2,
        )
    face_ids = np.flatnonzero(disk).astype(np.int64)
    vertices, triangles = submesh(faces, face_ids)
    loop = boundary_loops(triangles)[0]
    start, count = split_hairline(character.vertices[vertices[loop]], frame)
    loop = _rotate_to(loop, start)
    front, back = loop[:count], loop[count:]
    corners = turning_points(character.vertices[vertices[front]], frame)
    return Scalp(face_ids, vertices, triangles, loop, front, back, corners, rings, strays)


def split_boundary_ears(points: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Split the scalp's *ears*: triangles with two edges on the hairline.

    An ear's three corners are all hairline vertices, so a hairline edit that straightens
    the hairline there prescribes a flat, zero-area triangle for the membrane (Eq. 15), and
    every subdivision keeps an ear at the tip. The ear's inner edge gets its midpoint,
    which splits the ear and its neighbour across that edge in two each: every new triangle
    has at most one hairline edge and the midpoint is an interior (free) vertex. The
    midpoint of a head edge lies on the head, so the copy stays on it; the hairline loop
    and the orientation are unchanged. An ear whose neighbour is also an ear (a two-triangle
    scalp) is left.

    Parameters
    ----------
    points : (n, d) float64
        Per-vertex values that are affine along the head's edges (positions, parameters).
    triangles : (k, 3) int64
        A disk, consistently oriented.

    Returns
    -------
    points : (n + e, d) float64
        The input rows, then one midpoint per split ear.
    triangles : (k + 2e, 3) int64
    split : int
        Ears split (``e``).
    """
    points = np.array(points, dtype=np.float64)
    triangles = np.array(triangles, dtype=np.int64)
    split = 0
    skipped: set[int] = set()
    # a handful of ears per scalp: one at a time, the edge table re-derived after each
    while True:
        on_boundary = boundary_edges(triangles, len(points))
        ears = [int(e) for e in np.flatnonzero(on_boundary.sum(axis=1) == 2) if int(e) not in skipped]
        if not ears:
            return points, triangles, split
        ear = ears[0]
        inner = int(np.flatnonzero(~on_boundary[ear])[0])
        c, a, tip = (triangles[ear, (inner + j) % 3] for j in range(3))
        # the neighbour holds the inner edge the other way round: a -> c
        holds = (triangles == a) & (np.roll(triangles, -1, axis=1) == c)
        other, edge = np.argwhere(holds)[0]
        if on_boundary[other].sum() >= 2:
            skipped.add(ear)
            continue
        d = triangles[other, (edge + 2) % 3]
        middle = len(points)
        points = np.vstack([points, 0.5 * (points[a] + points[c])])
        triangles[ear] = (tip, c, middle)
        triangles[other] = (a, middle, d)
        triangles = np.vstack([triangles, [[tip, middle, a], [middle, c, d]]])
        split += 1


def refine_scalp(
    points: np.ndarray, triangles: np.ndarray, boundary: np.ndarray, min_triangles: int = DEFAULT_MIN_TRIANGLES
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A refined copy of the scalp for the membrane: 1-to-4 midpoint subdivision, repeated
    until there are at least ``min_triangles`` triangles.

    Every new edge lies inside one triangle of the input (or on its edge), so every midpoint
    lies on the input surface: the copy stays exactly on the head with no projection, and
    any per-vertex quantity that is affine inside each head triangle (3D positions, a
    piecewise-linear parameterization) is refined correctly by the same midpoints. Pass
    positions and parameters side by side (``(n, 3 + 2)``) to refine both at once. On the
    MakeHuman ``average-female`` head the scalp of a 300-strand ``short`` groom (seed 0) has
    466 faces, 264 vertices, a 60-vertex hairline and 16 mm mean edges; the default
    ``min_triangles`` gives one round: 1864 triangles, 993 vertices, a 120-vertex hairline,
    8 mm mean edges; two rounds give 7456 triangles, 3849 vertices, a 240-vertex hairline,
    4.0 mm mean edges (8.6 mm the longest).

    Parameters
    ----------
    points : (n, d) float64
        Per-vertex values of the scalp in local numbering (e.g. ``character.vertices[scalp.vertices]``).
    triangles : (k, 3) int64
    boundary : (b,) int64
        The hairline loop.
    min_triangles : int

    Returns
    -------
    points : (n', d) float64
        The input rows first, then the midpoints, round after round.
    triangles : (k', 3) int64
        Same orientation.
    boundary : (b',) int64
        The loop in its order with the new vertices inserted between, starting at the same
        vertex: after ``r`` rounds the old loop vertex ``i`` is at ``i * 2**r``.
    """
    points = np.asarray(points, dtype=np.float64)
    while len(triangles) < min_triangles:
        points, triangles, boundary = subdivide(points, triangles, boundary)
    return points.copy(), np.array(triangles, dtype=np.int64), np.array(boundary, dtype=np.int64)
