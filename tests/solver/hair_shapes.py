"""Small characters and hairstyles with known geometry, shared by the solver's unit tests.

* :func:`sphere_character`: an icosphere head of radius 0.1 m with a two-bone skeleton (neck,
  head) whose skin weights put every vertex on the head; :func:`outward_strands` grows
  straight strands from it, :func:`tilt_into_surface` turns them into the body.
* :func:`ellipsoid_head` (no skeleton) and :func:`hanging_groom`: strands rooted on the upper
  head that hang down along it a few mm outside.
* :func:`parallel_strands`: straight parallel strands in a plane, no body.
* :func:`model_of`: Eq. 7/10's :class:`ShapeModel` of a hairstyle; :func:`fine_problem`: a
  :class:`StrandProblem` of independent strands (Eq. 14's form).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import trimesh

from hairport.solver.adaptation.problem.energies import ShapeModel, unit_rows
from hairport.solver.adaptation.problem.strand_problem import StrandProblem
from hairport.solver.adaptation.source.neighbours import knn_other_strands, laplacian_operator
from hairport.solver.mesh.polyline import rest_lengths
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.mesh.triangles import interpolate_barycentric
from hairport.solver.model.character import Character, Skeleton
from hairport.solver.model.hair import Hair

#: radius (m) of the sphere head and the mean semi-axis of the ellipsoid head
HEAD_RADIUS = 0.1
#: segments per strand of :func:`hanging_groom`
SEGMENTS_PER_STRAND = 12
#: relative semi-axes of the ellipsoid head
HEAD_AXES = np.array([1.0, 0.9, 1.1])
#: rad: :func:`hanging_groom`'s strands hang down to this polar angle (a little below the equator)
STRAND_END_POLAR = 1.9
#: m: :func:`hanging_groom` keeps this from its source head
MIN_SOURCE_CLEARANCE = 1e-3


def sphere_character(scale=(1.0, 1.0, 1.0), shift=(0.0, 0.0, 0.0)) -> Character:
    """A rigged icosphere head (radius :data:`HEAD_RADIUS`), scaled per axis then shifted."""
    mesh = trimesh.creation.icosphere(3, radius=HEAD_RADIUS)
    m = np.asarray(scale)
    t = np.asarray(shift)
    skeleton = Skeleton(("neck_01", "head"), [-1, 0], [[0, -0.12, 0], [0, -0.04, 0]], [[0, -0.04, 0], [0, 0.07, 0]])
    skeleton = Skeleton(skeleton.names, skeleton.parents, skeleton.heads * m + t, skeleton.tails * m + t)
    weights = np.zeros((len(mesh.vertices), 2))
    weights[:, 1] = 1.0
    return Character(np.asarray(mesh.vertices) * m + t, mesh.faces, skeleton, sp.csr_matrix(weights), "sphere")


def outward_strands(character: Character, n_strands=40, n_points=8, seed=0) -> Hair:
    """Straight strands of 4 mm segments rooted on the upper half of ``character``, leaving
    along the surface normal tilted down."""
    rng = np.random.default_rng(seed)
    direction = rng.normal(size=(n_strands, 3))
    direction[:, 1] = np.abs(direction[:, 1]) + 0.2
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    sd = MeshQuery(character.vertices, character.faces).signed_distance(direction * 0.3)
    strands = [sd.closest[s] + np.outer(np.arange(n_points) * 0.004, sd.normal[s] + [0, -0.3, 0])
               for s in range(n_strands)]
    return Hair.from_strands(strands)


def tilt_into_surface(hair: Hair, query: MeshQuery, angle_from_normal: float) -> np.ndarray:
    """Each strand rigidly rotated about its root so it leaves at ``angle_from_normal`` (rad)
    from the surface normal: beyond pi/2 it dips into the body. Returns ``(N, 3)`` points."""
    points = hair.points.copy()
    roots = hair.roots
    sd = query.signed_distance(points[roots + 1])
    normal = sd.normal
    for s, r in enumerate(roots):
        rel = points[r:hair.offsets[s + 1]] - points[r]
        d = rel[1] / np.linalg.norm(rel[1])
        axis = np.cross(normal[s], d)
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(normal[s], [1.0, 0.0, 0.0])
        axis /= np.linalg.norm(axis)
        tangent = np.cross(axis, normal[s])
        goal = np.cos(angle_from_normal) * normal[s] + np.sin(angle_from_normal) * tangent
        # rotation taking d to goal about axis
        theta = np.arctan2(np.dot(np.cross(d, goal), axis), np.dot(d, goal))
        K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        R = np.eye(3) + np.sin(theta) * K + (1 - np.cos(theta)) * K @ K
        points[r:hair.offsets[s + 1]] = points[r] + rel @ R.T
    return points


def parallel_strands(n_strands=3, n_points=6, spacing=0.01, step=0.005) -> Hair:
    """Straight strands along -y, ``spacing`` (m) apart along x, particles ``step`` (m) apart."""
    strands = [np.stack([np.full(n_points, s * spacing), -step * np.arange(n_points), np.zeros(n_points)], axis=1)
               for s in range(n_strands)]
    return Hair.from_strands(strands)


def model_of(hair: Hair, k=5) -> ShapeModel:
    """Eq. 7/10 operators of ``hair`` with Eq. 8-9's ``k`` nearest particles of other strands."""
    nb = knn_other_strands(hair.points, hair.strand_of, k)
    K = laplacian_operator(nb, np.arange(hair.n_particles), hair.n_particles)
    return ShapeModel.build(hair.points, hair.segments, K)


def fine_problem(hair: Hair, start: np.ndarray, pull_weight: np.ndarray, pull_target: np.ndarray,
                 fixed: np.ndarray | None = None) -> StrandProblem:
    """A decoupled problem (Eq. 14 form: K diagonal) over ``hair``'s strands, from ``start (N, 3)``,
    each particle pulled with ``pull_weight (N,)`` towards ``pull_target (N, 3)``; roots fixed by default;
    with the spacing term's rest lengths for ``start`` as the initial transfer."""
    directions = np.zeros_like(hair.points)
    _, unit = unit_rows(hair.points[1:] - hair.points[:-1])
    directions[:-1] = unit
    return StrandProblem(
        hair.offsets, directions, start, sp.diags(pull_weight, format="csr"), pull_target,
        np.ones(hair.n_particles), hair.is_root if fixed is None else fixed, rest_lengths(hair.points, start, hair.offsets),
    )


def ellipsoid_head() -> Character:
    """An icosphere scaled to semi-axes :data:`HEAD_RADIUS` times :data:`HEAD_AXES` (no skeleton)."""
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=HEAD_RADIUS)
    vertices = np.asarray(mesh.vertices) * HEAD_AXES  # an ellipsoid, not a sphere
    return Character(vertices, np.asarray(mesh.faces), name="head")


def hanging_groom(head: Character, n_strands: int = 150, seed: int = 0) -> Hair:
    """Strands rooted exactly on the upper head, hanging down along it a few mm outside.

    Non-root particles lie on scaled copies (2-4 % larger) of the smooth ellipsoid whose
    vertices the head mesh interpolates, so they clear the (inscribed) mesh by > 1 mm.
    """
    rng = np.random.default_rng(seed)
    centroids = head.vertices[head.faces].mean(axis=1)
    candidates = np.flatnonzero(centroids[:, 2] > 0.5 * HEAD_RADIUS * HEAD_AXES[2])
    faces = rng.choice(candidates, n_strands)
    bary = rng.dirichlet(np.ones(3), n_strands)
    roots = interpolate_barycentric(head.vertices, head.faces, faces, bary)
    unit = roots / (HEAD_RADIUS * HEAD_AXES)
    polar0 = np.arccos(np.clip(unit[:, 2] / np.linalg.norm(unit, axis=1), -1, 1))
    azimuth = np.arctan2(unit[:, 1], unit[:, 0])
    k = np.arange(1, SEGMENTS_PER_STRAND + 1) / SEGMENTS_PER_STRAND  # (K,)
    polar = polar0[:, None] + k[None] * (STRAND_END_POLAR - polar0[:, None])  # (S, K)
    lift = 1.02 + 0.02 * k[None]
    on_sphere = np.stack(
        [np.sin(polar) * np.cos(azimuth[:, None]), np.sin(polar) * np.sin(azimuth[:, None]), np.cos(polar)], axis=2
    )
    rest = on_sphere * (lift[..., None] * HEAD_RADIUS * HEAD_AXES)
    points = np.concatenate([roots[:, None, :], rest], axis=1)
    hair = Hair(points.reshape(-1, 3), np.arange(n_strands + 1) * (SEGMENTS_PER_STRAND + 1))
    # keep the strands whose non-root particles clear the source head by MIN_SOURCE_CLEARANCE
    d = MeshQuery(head.vertices, head.faces).signed_distance(hair.points).distance
    ok_particle = (d >= MIN_SOURCE_CLEARANCE) | hair.is_root
    ok = np.logical_and.reduceat(ok_particle, hair.offsets[:-1])
    hair = hair.subset(np.flatnonzero(ok))
    thickness = np.linspace(1e-4, 5e-5, hair.n_particles)
    return Hair(hair.points, hair.offsets, thickness=thickness)
