"""The same shape on another topology: remeshed and cut characters, for the wrap tests.

A wrap (non-rigid registration of a source body onto a target of another topology) needs
targets whose vertices, triangles and vertex order have nothing to do with the source's,
while the truth stays known. :func:`remesh` turns a mesh into such a target; since the
MakeHuman presets share one topology, wrapping one preset onto a remeshed other preset has
the original preset's vertices as ground truth, vertex for vertex.

Methods
-------
``"isotropic"``
    Split every edge longer than :data:`REFINE_SHARE` of the target edge length (crack-free
    red-green templates, repeated), collapse the shortest edges (``igl.decimate``, midpoint
    placement) down to the asked vertex count, then relax tangentially and project onto the
    original surface a few times: near-equilateral triangles of one size (edge lengths spread
    by ~0.18 of their mean, against 0.93 on the MakeHuman body; smallest angle ~9-20 degrees).
``"decimate"``
    Loop-subdivide (smooths the piecewise-flat original, so that no output vertex lands on an
    original one) until there are twice the asked vertices, collapse by quadric error
    (``igl.qslim``), project onto the original surface: curvature-adaptive triangles of very
    different sizes and shapes, as a game asset's LOD has (spread ~0.55, smallest angle ~1 degree).

Both give one closed surface for a closed input (the MakeHuman body is watertight, genus 0,
no holes at the eyes or mouth), with the asked vertex count (exactly for a closed genus-0
input), then vertex order, face order and each face's first corner shuffled with the seed.
The seed also moves the vertices of the dense mesh a little within the surface before the
collapses (:func:`_jittered`), so two seeds give two different triangulations; one seed gives
the same arrays every time.

Cuts (:func:`cut_above`, :func:`head_cut`, :func:`bust_cut`) keep the faces whose every
corner lies above a horizontal plane (as :mod:`.makehuman.bust` cuts), the largest connected
piece of them and the vertices they use, in their input order.

Where the original folds onto itself (the lips, between the toes and fingers, the ears) a
remesh has a few dozen faces in folds, as the original has; at 5k vertices (21 mm edges) the
fingers and toes lose their tips (up to ~40 mm from the original there; the head stays within
~15 mm, ~1 mm on average).

Measured on ``heavy-male`` (13,380 vertices), CPU seconds on a loaded 2-core machine:
isotropic 0.2 / 0.5 / 2.7 s and decimate 1.3 / 0.9 / 5.2 s for 5k / 20k / 100k vertices;
mean surface distance to the original 0.6 / 0.18 / 0.04 mm (isotropic) and 0.3 / 0.09 /
0.04 mm (decimate).
"""

from __future__ import annotations

import igl
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from hairport.solver.mesh.topology import face_adjacency, submesh
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError
from hairport.solver.synthetic.makehuman.bust import cut_height

#: the remeshing methods of :func:`remesh`
METHODS = ("isotropic", "decimate")
#: fewest vertices :func:`remesh` makes (below this a body is no longer a body)
MIN_TARGET_VERTICES = 100
#: isotropic: split edges longer than this share of the target edge length before collapsing (1.0:
#: ~1.5x the collapses for an edge-length spread 0.17 instead of 0.18)
REFINE_SHARE = 1.25
#: isotropic: rounds of tangential relaxation + projection, and the share of the way to the
#: neighbours' mean moved per round (more rounds: rounder triangles, slower)
RELAX_ROUNDS = 3
RELAX_STEP = 0.5
#: the seed moves every vertex of the dense mesh, within its tangent plane, by up to this share of the
#: smallest altitude of its triangles (so no triangle flips): other edge lengths and quadrics, so
#: another sequence of collapses, not only another order
JITTER_SHARE = 0.2
#: decimate: Loop-subdivide until the mesh has this many times the asked vertices
LOOP_FACTOR = 2
#: decimate: a projected vertex whose faces would get an angle below this (degrees) stays put
MIN_PROJECTED_ANGLE_DEG = 1.0
#: the vertical axis of the MakeHuman frame (+Y up)
UP_AXIS = 1
#: the default head cut: a tenth of the way up the neck bone (every preset then has one border loop;
#: from about 0.3 up the plane also cuts the mouth cavity, which reaches down into the neck)
NECK_BONE = "neck_01"
NECK_BONE_PARAMETER = 0.1


def target_edge_length(area: float, n_vertices: int) -> float:
    """Edge length (m) of equilateral triangles that tile ``area`` (m²) with ``n_vertices`` vertices
    (a closed triangle mesh has about two faces per vertex)."""
    return float(np.sqrt(4.0 * area / (np.sqrt(3.0) * 2.0 * n_vertices)))


def _unique_edges(faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """The undirected edges ``(E, 2)`` and, per face corner ``j``, the id of edge ``j -> j + 1`` ``(F, 3)``."""
    half = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 3, 2)
    key = np.minimum(half[..., 0], half[..., 1]) * n_vertices + np.maximum(half[..., 0], half[..., 1])
    unique, inverse = np.unique(key.ravel(), return_inverse=True)
    return np.stack([unique // n_vertices, unique % n_vertices], axis=1), inverse.reshape(-1, 3)


def _split_templates(points: np.ndarray, faces: np.ndarray, mid: np.ndarray) -> np.ndarray:
    """The triangles of faces ``(F, 3)`` with the midpoints ``mid (F, 3)`` (of edge ``j -> j + 1``,
    -1 where it is not split), orientation kept; a quad left by two splits takes its shorter diagonal."""
    split = mid >= 0
    count = split.sum(axis=1)
    out = [faces[count == 0]]
    for turn in range(3):
        order = [turn, (turn + 1) % 3, (turn + 2) % 3]
        f, m, s = faces[:, order], mid[:, order], split[:, order]
        one = (count == 1) & s[:, 0]
        a, b, c = f[one].T
        out += [np.stack([a, m[one, 0], c], 1), np.stack([m[one, 0], b, c], 1)]
        two = (count == 2) & s[:, 0] & s[:, 1]
        a, b, c = f[two].T
        m0, m1 = m[two, 0], m[two, 1]
        out.append(np.stack([m0, b, m1], 1))
        short = (np.linalg.norm(points[a] - points[m1], axis=1)
                 <= np.linalg.norm(points[m0] - points[c], axis=1))[:, None]
        out += [np.where(short, np.stack([a, m0, m1], 1), np.stack([a, m0, c], 1)),
                np.where(short, np.stack([a, m1, c], 1), np.stack([m0, m1, c], 1))]
    three = count == 3
    a, b, c = faces[three].T
    m0, m1, m2 = mid[three].T
    out += [np.stack([a, m0, m2], 1), np.stack([m0, b, m1], 1), np.stack([m2, m1, c], 1), np.stack([m0, m1, m2], 1)]
    return np.concatenate(out).astype(np.int64)


def split_long_edges(vertices: np.ndarray, faces: np.ndarray, max_length: float) -> tuple[np.ndarray, np.ndarray]:
    """Halve every edge longer than ``max_length`` (m), repeatedly, until none is; crack-free.

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    max_length : float

    Returns
    -------
    vertices : (V', 3) float64
        The input vertices first, then the midpoints (on the original flat triangles).
    faces : (F', 3) int64
        Same orientation as the input.
    """
    vertices, faces = np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)
    while True:
        n = len(vertices)
        edges, corner_edge = _unique_edges(faces, n)
        long = np.linalg.norm(vertices[edges[:, 0]] - vertices[edges[:, 1]], axis=1) > max_length
        if not long.any():
            return vertices, faces
        mid_id = np.full(len(edges), -1, dtype=np.int64)
        mid_id[long] = n + np.arange(int(long.sum()))
        vertices = np.concatenate([vertices, 0.5 * (vertices[edges[long, 0]] + vertices[edges[long, 1]])])
        faces = _split_templates(vertices, faces, mid_id[corner_edge])


def _shuffled(vertices: np.ndarray, faces: np.ndarray, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Random vertex order, face order and first corner of each face (orientation kept)."""
    order = rng.permutation(len(vertices))
    new_id = np.empty_like(order)
    new_id[order] = np.arange(len(order))
    faces = new_id[faces[rng.permutation(len(faces))]]
    turn = rng.integers(0, 3, len(faces))
    corners = (np.arange(3)[None, :] + turn[:, None]) % 3
    return vertices[order], np.take_along_axis(faces, corners, axis=1)


def _jittered(vertices: np.ndarray, faces: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """``vertices`` moved at random within their tangent planes by up to :data:`JITTER_SHARE` of the
    smallest altitude of the triangles around them."""
    double_area = igl.doublearea(vertices, faces)
    opposite = np.linalg.norm(vertices[faces[:, [1, 2, 0]]] - vertices[faces[:, [2, 0, 1]]], axis=2)
    altitude = np.full(len(vertices), np.inf)
    np.minimum.at(altitude, faces.ravel(), (double_area[:, None] / opposite).ravel())
    normals = igl.per_vertex_normals(vertices, faces)
    step = rng.normal(size=vertices.shape)
    step -= np.einsum("ij,ij->i", step, normals)[:, None] * normals
    step /= np.maximum(np.linalg.norm(step, axis=1, keepdims=True), np.finfo(float).tiny)
    return vertices + step * (JITTER_SHARE * altitude * rng.random(len(vertices)))[:, None]


def _target_faces(vertices: np.ndarray, faces: np.ndarray, target_vertices: int, edge: float) -> int:
    """Faces to collapse down to for ``target_vertices``: ``F = 2 (V - chi) - B`` with the
    border edge count ``B`` estimated from the border's length and the target ``edge`` (m)."""
    edges, corner_edge = _unique_edges(faces, len(vertices))
    uses = np.bincount(corner_edge.ravel(), minlength=len(edges))
    border = edges[uses == 1]
    chi = len(np.unique(faces)) - len(edges) + len(faces)
    border_edges = np.linalg.norm(vertices[border[:, 0]] - vertices[border[:, 1]], axis=1).sum() / edge
    return max(int(round(2 * (target_vertices - chi) - border_edges)), 4)


def _relax(points: np.ndarray, faces: np.ndarray, tree: igl.AABB, original: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """:data:`RELAX_ROUNDS` of moving each inner vertex toward its neighbours' mean within its tangent
    plane, then onto the original surface; border vertices stay."""
    n = len(points)
    rows, cols = faces[:, [0, 1, 2, 1, 2, 0]].ravel(), faces[:, [1, 2, 0, 0, 1, 2]].ravel()
    adjacency = sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    adjacency.data[:] = 1.0  # each edge once, whichever faces hold it
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    edges, corner_edge = _unique_edges(faces, n)
    border = edges[np.bincount(corner_edge.ravel(), minlength=len(edges)) == 1].ravel()
    moving = np.ones(n, dtype=bool)
    moving[border] = False
    for _ in range(RELAX_ROUNDS):
        normals = igl.per_vertex_normals(points, faces)
        step = (adjacency @ points) / degree[:, None] - points
        step -= np.einsum("ij,ij->i", step, normals)[:, None] * normals
        moved = points + RELAX_STEP * step * moving[:, None]
        points = tree.squared_distance(*original, moved)[2]
    return points


def _min_angles(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) float64: each face's smallest inner angle (degrees)."""
    return np.degrees(igl.internal_angles(vertices, faces).min(axis=1))


def _project_keeping_shape(points: np.ndarray, faces: np.ndarray, tree: igl.AABB,
                           original: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """``points`` moved onto the original surface, except the corners of faces whose smallest
    angle the move would push below :data:`MIN_PROJECTED_ANGLE_DEG`."""
    projected = tree.squared_distance(*original, points)[2]
    after = _min_angles(projected, faces)
    bad = (after < MIN_PROJECTED_ANGLE_DEG) & (after < _min_angles(points, faces))
    projected[np.unique(faces[bad])] = points[np.unique(faces[bad])]
    return projected


def _loop_until(vertices: np.ndarray, faces: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """Loop subdivision, at least once, until the mesh has ``n_vertices`` vertices or more."""
    while True:
        vertices, faces = igl.loop(vertices, faces, 1)
        if len(vertices) >= n_vertices:
            return vertices, faces.astype(np.int64)


def remesh(vertices: np.ndarray, faces: np.ndarray, target_vertices: int, method: str = "isotropic",
           seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The same surface with another topology (see the module docstring for the methods).

    Parameters
    ----------
    vertices : (V, 3) float64
        Meters.
    faces : (F, 3) int64
        A manifold mesh, counter-clockwise seen from outside (borders allowed).
    target_vertices : int
        Vertices wanted: exact for a closed genus-0 mesh, within a few percent with borders.
    method : {"isotropic", "decimate"}
    seed : int
        Moves the dense mesh's vertices a little before the collapses (another triangulation per
        seed) and shuffles the output's vertex order, face order and first corners.

    Returns
    -------
    vertices : (V', 3) float64
        On (isotropic) or near (decimate: where projecting would flatten a face) the input surface.
    faces : (F', 3) int64
        Same orientation as the input.
    """
    if method not in METHODS:
        raise InputError(f"unknown remesh method {method!r}; expected one of {', '.join(METHODS)}", "method",
                         "bad_option")
    if target_vertices < MIN_TARGET_VERTICES:
        raise InputError(f"remesh to {target_vertices} vertices: at least {MIN_TARGET_VERTICES} are needed",
                         "target_vertices", "bad_option")
    original = (np.ascontiguousarray(vertices, dtype=np.float64), np.ascontiguousarray(faces, dtype=np.int64))
    rng = np.random.default_rng(seed)
    tree = igl.AABB()
    tree.init(*original)
    edge = target_edge_length(float(igl.doublearea(*original).sum() / 2.0), target_vertices)
    n_faces = _target_faces(*original, target_vertices, edge)
    if method == "isotropic":
        dense = _shuffled(*split_long_edges(*original, REFINE_SHARE * edge), rng)
        dense = (_jittered(*dense, rng), dense[1])
        points, triangles = igl.decimate(*dense, n_faces, False)[:2]
        points = _relax(points, triangles, tree, original)
    else:
        dense = _shuffled(*_loop_until(*original, LOOP_FACTOR * target_vertices), rng)
        dense = (_jittered(*dense, rng), dense[1])
        points, triangles = igl.qslim(*dense, n_faces, False)[:2]
        points = _project_keeping_shape(points, triangles, tree, original)
    return _shuffled(np.ascontiguousarray(points, dtype=np.float64), np.asarray(triangles, dtype=np.int64), rng)


def remeshed_character(character: Character, target_vertices: int, method: str = "isotropic",
                       seed: int = 0) -> Character:
    """``character``'s body remeshed by :func:`remesh`, without skeleton or weights (a remeshed
    target has no rig), named ``<name>~<method>-<target_vertices>-s<seed>``."""
    points, triangles = remesh(character.vertices, character.faces, target_vertices, method, seed)
    return Character(points, triangles, name=f"{character.name}~{method}-{target_vertices}-s{seed}")


def cut_above(vertices: np.ndarray, faces: np.ndarray, height: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The part of a mesh above a horizontal plane.

    Keeps the faces whose every corner is at or above ``height`` (m along +Y), then the largest
    edge-connected piece of them (a plane through the arms would leave hands behind).

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    height : float

    Returns
    -------
    vertices : (n, 3) float64
        The vertices the kept faces use, in their input order.
    faces : (k, 3) int64
        Into those, orientation kept.
    kept : (n,) int64
        Each kept vertex's id in the input (ascending).
    """
    vertices, faces = np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64)
    above = np.flatnonzero((vertices[faces, UP_AXIS] >= height).all(axis=1))
    if len(above) == 0:
        raise InputError(f"no face lies above {height:.3f} m", "height", "bad_option")
    _, labels = connected_components(face_adjacency(faces[above]), directed=False)
    above = above[labels == np.argmax(np.bincount(labels))]
    kept, triangles = submesh(faces, above)
    return vertices[kept], triangles, kept


def bone_height(character: Character, bone: str, parameter: float) -> float:
    """Height (m along +Y) of the point ``parameter`` of the way from ``bone``'s head to its tail."""
    if character.skeleton is None:
        raise InputError(f"{character.name} has no skeleton: give the cut height", character.name, "bad_skeleton")
    index = character.skeleton.index(bone)
    head, tail = character.skeleton.heads[index], character.skeleton.tails[index]
    return float(head[UP_AXIS] + parameter * (tail[UP_AXIS] - head[UP_AXIS]))


def neck_height(character: Character) -> float:
    """The default head cut's height (m): :data:`NECK_BONE_PARAMETER` of the way up :data:`NECK_BONE`."""
    return bone_height(character, NECK_BONE, NECK_BONE_PARAMETER)


def chest_height(character: Character) -> float:
    """The default bust cut's height (m): the chest plane of :func:`.makehuman.bust.cut_height`."""
    if character.skeleton is None:
        raise InputError(f"{character.name} has no skeleton: give the cut height", character.name, "bad_skeleton")
    return cut_height(character)


def cut_character(character: Character, height: float, label: str = "cut") -> tuple[Character, np.ndarray]:
    """:func:`cut_above` on a character, keeping its rig (weights of the kept vertices).

    Returns
    -------
    character : Character
        Named ``<name>/<label>``.
    kept : (n,) int64
        Each kept vertex's id in ``character``.
    """
    points, triangles, kept = cut_above(character.vertices, character.faces, height)
    weights = None if character.weights is None else character.weights[kept]
    return Character(points, triangles, character.skeleton, weights, f"{character.name}/{label}"), kept


def head_cut(character: Character, height: float | None = None) -> tuple[Character, np.ndarray]:
    """The head and upper neck: :func:`cut_character` at ``height`` (default :func:`neck_height`;
    give it, e.g. from the original preset, for a character without a skeleton)."""
    return cut_character(character, neck_height(character) if height is None else height, "head")


def bust_cut(character: Character, height: float | None = None) -> tuple[Character, np.ndarray]:
    """Head, shoulders, upper arms and chest: :func:`cut_character` at ``height`` (default
    :func:`chest_height`)."""
    return cut_character(character, chest_height(character) if height is None else height, "bust")


def surface_distances(vertices_a: np.ndarray, faces_a: np.ndarray, vertices_b: np.ndarray, faces_b: np.ndarray,
                      n_samples: int = 100_000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Distances (m) from area-uniform samples of each surface to the other one.

    Parameters
    ----------
    vertices_a, vertices_b : (Va, 3), (Vb, 3) float64
    faces_a, faces_b : (Fa, 3), (Fb, 3) int64
    n_samples : int
        Samples per surface.
    seed : int

    Returns
    -------
    a_to_b : (n_samples,) float64
    b_to_a : (n_samples,) float64
    """
    rng = np.random.default_rng(seed)

    def distances(points, faces, other_points, other_faces):
        samples = _surface_samples(points, faces, n_samples, rng)
        return np.sqrt(igl.point_mesh_squared_distance(samples, other_points, other_faces)[0])

    a = (np.asarray(vertices_a, dtype=np.float64), np.asarray(faces_a, dtype=np.int64))
    b = (np.asarray(vertices_b, dtype=np.float64), np.asarray(faces_b, dtype=np.int64))
    return distances(*a, *b), distances(*b, *a)


def _surface_samples(vertices: np.ndarray, faces: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 3) float64: points uniform by area on the mesh."""
    area = igl.doublearea(vertices, faces)
    face = rng.choice(len(faces), n, p=area / area.sum())
    u = rng.random((n, 2))
    flip = u.sum(axis=1) > 1.0  # fold the unit square onto the triangle
    u[flip] = 1.0 - u[flip]
    corners = vertices[faces[face]]
    return corners[:, 0] + u[:, :1] * (corners[:, 1] - corners[:, 0]) + u[:, 1:] * (corners[:, 2] - corners[:, 0])
