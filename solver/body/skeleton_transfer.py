"""Skeleton transfer between characters of one topology by a joint regressor.

A joint regressor writes every joint (each bone's head and tail) as a fixed affine
combination of the source's surface vertices, ``joint = sum_v w_v x_v`` with
``sum_v w_v = 1``; evaluated on a target of the same topology it places the target's
joints. This is how MakeHuman rigs place joints (as means of helper vertices) and how
SMPL's joint regressor works, with weights fitted here in closed form.

Support set. Joints lie inside the body, so the vertices that carry a joint should
surround it on all sides; then the joint is (nearly) their centroid and follows the
local cross-section when the body gets wider, narrower, taller or shifted. For each
joint, :data:`DEFAULT_RAY_DIRECTIONS` rays are cast from the joint in directions spread
evenly over the sphere; the corners of every hit triangle whose hit distance is at most
:data:`FAR_HIT_FACTOR` times the median hit distance join the support (this keeps the
ring around a limb and drops the far hits along it, e.g. the hand seen from the elbow),
together with the :data:`DEFAULT_NEAREST` nearest vertices. Where that support is too
small or too flat (few rays hit: a joint outside or on an open mesh), it is grown with
the nearest vertices (:data:`FALLBACK_NEAREST`, doubled until well conditioned).

Weights. Over a support of K vertices with centroid ``c`` and centred positions ``X'``
(K, 3), the weights closest to uniform, ``min ||w - 1/K||^2`` subject to ``sum w = 1``
and ``X^T w = joint``, have the closed form (the KKT system decouples because the columns
of ``X'`` sum to zero)::

    w = 1/K + X' (X'^T X')^-1 (joint - c)

Any such affine combination reproduces the source joints exactly (reflexive) and commutes
with affine maps of the body: a target ``A x + t`` gets the joints ``A j + t``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.character import Character, Skeleton, check_same_topology
from hairport.solver.model.errors import InputError

#: rays cast from each joint to find the vertices around it
DEFAULT_RAY_DIRECTIONS = 64
#: ray hits farther than this times the joint's median hit distance are left out
FAR_HIT_FACTOR = 2.0
#: nearest vertices always added to a joint's support
DEFAULT_NEAREST = 8
#: first size of the nearest-vertex set used to grow a support that is too small or flat
FALLBACK_NEAREST = 24
#: a support needs at least this many vertices ...
MIN_SUPPORT = 12
#: ... and a scatter whose smallest / largest eigenvalue ratio is at least this (unitless)
MIN_CONDITIONING = 1e-3


@dataclass(frozen=True, eq=False)
class JointRegressor:
    """Joints of a skeleton as fixed affine combinations of mesh vertices.

    Attributes
    ----------
    names : tuple of str, length B
    parents : (B,) int64
    matrix : (2B, V) scipy.sparse.csr_matrix
        Row ``b`` gives bone ``b``'s head, row ``B + b`` its tail; every row sums to 1.
    """

    names: tuple[str, ...]
    parents: np.ndarray
    matrix: sp.csr_matrix

    @property
    def n_bones(self) -> int:
        return len(self.names)

    @property
    def n_vertices(self) -> int:
        return self.matrix.shape[1]

    def joints(self, vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Heads and tails on a mesh of the same topology.

        Parameters
        ----------
        vertices : (V, 3) float64

        Returns
        -------
        heads, tails : (B, 3) float64
        """
        vertices = np.asarray(vertices, dtype=np.float64)
        if vertices.shape != (self.n_vertices, 3):
            raise InputError(
                f"vertices have shape {vertices.shape}, the joint regressor needs ({self.n_vertices}, 3)",
                code="topology_mismatch",
            )
        joints = self.matrix @ vertices
        return joints[: self.n_bones], joints[self.n_bones :]

    def apply(self, vertices: np.ndarray) -> Skeleton:
        """The skeleton placed on a mesh of the same topology.

        Parameters
        ----------
        vertices : (V, 3) float64

        Returns
        -------
        skeleton : Skeleton
        """
        heads, tails = self.joints(vertices)
        return Skeleton(self.names, self.parents, heads, tails)


def fit_joint_regressor(
    character: Character,
    *,
    n_directions: int = DEFAULT_RAY_DIRECTIONS,
    far_factor: float = FAR_HIT_FACTOR,
    n_nearest: int = DEFAULT_NEAREST,
    query: MeshQuery | None = None,
) -> JointRegressor:
    """Fit a joint regressor to a rigged character (see the module docstring).

    Parameters
    ----------
    character : Character
        With a skeleton.
    n_directions : int
        Rays cast per joint.
    far_factor : float
        Hits farther than ``far_factor`` times the median hit distance are not used.
    n_nearest : int
        Nearest vertices always in a joint's support.
    query : MeshQuery, optional
        A prebuilt query structure over the character's mesh.

    Returns
    -------
    regressor : JointRegressor
        Reproduces the character's joints from its vertices (to rounding).
    """
    skeleton = character.skeleton
    if skeleton is None:
        raise InputError("the character has no skeleton to fit a joint regressor to", character.name, "no_skeleton")
    vertices = character.vertices
    n_vertices = len(vertices)
    all_joints = np.concatenate([skeleton.heads, skeleton.tails])
    # coincident joints (a child's head on its parent's tail) get one row: they stay
    # exactly coincident on every target
    joints, inverse = np.unique(all_joints, axis=0, return_inverse=True)
    inverse = inverse.ravel()
    query = query or MeshQuery(vertices, character.faces)
    tree = cKDTree(vertices)

    support = np.concatenate(
        [
            _ray_support(query, character.faces, joints, n_directions, far_factor),
            _nearest(tree, joints, min(n_nearest, n_vertices)),
        ],
        axis=1,
    )
    support = _dedupe_rows(support)
    weights, good = _affine_weights(vertices, support, joints)
    k = FALLBACK_NEAREST
    while not good.all():
        k = min(k, n_vertices)
        bad = np.flatnonzero(~good)
        grown = _dedupe_rows(np.concatenate([support[bad], _nearest(tree, joints[bad], k)], axis=1))
        grown_weights, grown_good = _affine_weights(vertices, grown, joints[bad])
        width = max(support.shape[1], grown.shape[1])
        support, weights = _pad(support, width, -1), _pad(weights, width, 0.0)
        support[bad], weights[bad] = _pad(grown, width, -1), _pad(grown_weights, width, 0.0)
        good[bad] = grown_good
        if k >= n_vertices:
            break  # a degenerate (flat) mesh: keep the least-squares weights
        k *= 2

    valid = support >= 0
    rows = np.broadcast_to(np.arange(len(joints))[:, None], support.shape)[valid]
    unique_matrix = sp.csr_matrix((weights[valid], (rows, support[valid])), shape=(len(joints), n_vertices))
    matrix = sp.csr_matrix(unique_matrix[inverse])
    return JointRegressor(skeleton.names, skeleton.parents.copy(), matrix)


def transfer_skeleton(
    source: Character, target_vertices: np.ndarray, *, regressor: JointRegressor | None = None
) -> Skeleton:
    """The source's skeleton placed on a target mesh of the same topology.

    Parameters
    ----------
    source : Character
        With a skeleton.
    target_vertices : (V, 3) float64
        The target's vertices, vertex for vertex with the source.
    regressor : JointRegressor, optional
        From :func:`fit_joint_regressor` on ``source`` (fitted here when not given).

    Returns
    -------
    skeleton : Skeleton
        Same bone names and parents as the source. The source's skin weights apply to the
        target unchanged (same topology).
    """
    target_vertices = np.asarray(target_vertices, dtype=np.float64)
    if target_vertices.shape != source.vertices.shape:
        raise InputError(
            f"target vertices have shape {target_vertices.shape}, the source {source.name} has "
            f"{source.vertices.shape}",
            code="topology_mismatch",
        )
    if not np.isfinite(target_vertices).all():
        raise InputError("target vertices are not all finite", code="non_finite")
    regressor = regressor or fit_joint_regressor(source)
    return regressor.apply(target_vertices)


def ensure_skeleton(
    source: Character, target: Character, *, regressor: JointRegressor | None = None
) -> Character:
    """The target, rigged with the source's skeleton and skin weights if it has no skeleton.

    Parameters
    ----------
    source : Character
    target : Character
        Same topology as ``source`` (checked first).
    regressor : JointRegressor, optional
        From :func:`fit_joint_regressor` on ``source``.

    Returns
    -------
    target : Character
        ``target`` itself when it already has a skeleton; otherwise its mesh with the
        transferred skeleton and the source's skin weights (``None`` if the source has none).

    Raises
    ------
    TopologyMismatch
    InputError
        Neither character has a skeleton.
    """
    check_same_topology(source, target)
    if target.skeleton is not None:
        return target
    if source.skeleton is None:
        raise InputError(
            f"neither the source {source.name} nor the target {target.name} has a skeleton",
            target.name,
            "no_skeleton",
        )
    skeleton = transfer_skeleton(source, target.vertices, regressor=regressor)
    return Character(target.vertices, target.faces, skeleton, source.weights, target.name)


def sphere_directions(n: int) -> np.ndarray:
    """Unit vectors spread evenly over the sphere (Fibonacci lattice).

    Parameters
    ----------
    n : int

    Returns
    -------
    directions : (n, 3) float64
    """
    i = np.arange(n, dtype=np.float64) + 0.5
    z = 1.0 - 2.0 * i / n
    radius = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    angle = np.pi * (3.0 - np.sqrt(5.0)) * i
    return np.stack([radius * np.cos(angle), radius * np.sin(angle), z], axis=1)


def _ray_support(
    query: MeshQuery, faces: np.ndarray, joints: np.ndarray, n_directions: int, far_factor: float
) -> np.ndarray:
    """(J, 3 n_directions) int64 corners of the near hit triangles around each joint, -1 padded."""
    if n_directions <= 0:
        return np.full((len(joints), 0), -1, dtype=np.int64)
    directions = sphere_directions(n_directions)
    origins = np.repeat(joints, n_directions, axis=0)
    hits = query.first_hits(origins, np.tile(directions, (len(joints), 1)))
    hit = hits.hit.reshape(len(joints), n_directions)
    distance = hits.distance.reshape(len(joints), n_directions)
    face = hits.faces.reshape(len(joints), n_directions)
    n_hits = hit.sum(axis=1)
    sorted_distance = np.sort(np.where(hit, distance, np.inf), axis=1)
    median = sorted_distance[np.arange(len(joints)), np.maximum(n_hits - 1, 0) // 2]
    keep = hit & (distance <= far_factor * median[:, None])
    corners = np.where(keep[..., None], faces[np.maximum(face, 0)], -1)
    return corners.reshape(len(joints), -1)


def _nearest(tree: cKDTree, points: np.ndarray, k: int) -> np.ndarray:
    """(N, k) int64 indices of the k nearest vertices."""
    if k <= 0:
        return np.full((len(points), 0), -1, dtype=np.int64)
    _, index = tree.query(points, k=k)
    return np.asarray(index, dtype=np.int64).reshape(len(points), k)


def _dedupe_rows(ids: np.ndarray) -> np.ndarray:
    """Each row sorted with repeated indices replaced by -1 (padding)."""
    ids = np.sort(ids, axis=1)
    repeated = np.zeros_like(ids, dtype=bool)
    repeated[:, 1:] = ids[:, 1:] == ids[:, :-1]
    return np.where(repeated, -1, ids)


def _pad(array: np.ndarray, width: int, value) -> np.ndarray:
    if array.shape[1] >= width:
        return array
    padding = np.full((len(array), width - array.shape[1]), value, dtype=array.dtype)
    return np.concatenate([array, padding], axis=1)


def _affine_weights(vertices: np.ndarray, support: np.ndarray, joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest-to-uniform affine weights reproducing each joint from its support.

    Parameters
    ----------
    vertices : (V, 3) float64
    support : (J, K) int64
        Vertex indices, -1 for padding.
    joints : (J, 3) float64

    Returns
    -------
    weights : (J, K) float64
        Zero on padding; each row sums to 1 and reproduces its joint.
    good : (J,) bool
        The support is large enough and not flat (:data:`MIN_SUPPORT`,
        :data:`MIN_CONDITIONING`).
    """
    valid = support >= 0
    mask = valid.astype(np.float64)
    count = mask.sum(axis=1)
    safe_count = np.maximum(count, 1.0)
    points = vertices[np.maximum(support, 0)] * mask[..., None]
    centroid = points.sum(axis=1) / safe_count[:, None]
    centred = (points - centroid[:, None, :]) * mask[..., None]
    scatter = np.einsum("jki,jkl->jil", centred, centred)
    eigenvalues = np.linalg.eigvalsh(scatter)
    conditioning = eigenvalues[:, 0] / np.maximum(eigenvalues[:, 2], np.finfo(float).tiny)
    inverse = np.linalg.pinv(scatter, hermitian=True)
    weights = mask / safe_count[:, None] + np.einsum(
        "jki,ji->jk", centred, np.einsum("jil,jl->ji", inverse, joints - centroid)
    )
    # one step of iterative refinement, then restore the exact sum
    residual = joints - np.einsum("jk,jki->ji", weights, points)
    weights += np.einsum("jki,ji->jk", centred, np.einsum("jil,jl->ji", inverse, residual))
    weights += mask * ((1.0 - weights.sum(axis=1)) / safe_count)[:, None]
    good = (count >= MIN_SUPPORT) & (conditioning >= MIN_CONDITIONING)
    return weights, good
