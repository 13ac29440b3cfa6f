"""Naive hairstyle retargeting baselines: cheap previews and the yardstick for the main method.

These are the transfers users would otherwise do by hand or in a game engine (design notes
section 5, paper Fig. 2b-c). Every baseline first *anchors* each strand root on the source
mesh (closest point -> face + barycentric coordinates) and re-evaluates that anchor on the
target mesh (same topology), giving the root target: the root anchoring of the initial
transfer (:func:`.transfer.anchors.surface_anchors`, :func:`.transfer.anchors.root_targets`).
Then:

``global-translate``  (Fig. 2b, top)
    The whole hairstyle moves by the mean root displacement.
``root-translate``  (Fig. 2b, bottom)
    Each strand moves by its own root displacement.
``root-rigid``
    Each strand is translated with its root and rotated with the surface frame of the root's
    face, ``R = F_t F_s^T``.
``affine-translate``  (Fig. 2c)
    A least-squares affine map of the head region is applied to the whole hairstyle, then
    each strand is translated so that its root lands on its root target.
``rbf-warp``  (what game-engine groom binding does)
    A thin-plate-spline displacement field of space, fitted to the body's vertex
    displacements near the hair, moves every particle; roots are then snapped to their
    root targets.

Any method may be followed by :func:`push_out` (method suffix ``+pushout``), which moves
every non-root particle closer than ``clearance`` to the target body out along the distance
normal.

Conventions: points in meters, hairstyles in the CSR layout of :class:`~.model.hair.Hair`.
The methods place roots exactly on their root targets; roots that were not on the source
surface are therefore projected onto it (the reflexive test source == target is exact for
roots on the surface, and moves an off-surface root by its distance to the surface).
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from scipy.interpolate import RBFInterpolator

from hairport.solver.mesh.clearance import push_out
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.mesh.triangles import face_frames
from hairport.solver.model.character import Character, check_same_topology
from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import Hair
from hairport.solver.transfer.anchors import root_targets, surface_anchors

#: the method names accepted by :func:`retarget_baseline` (each may carry :data:`PUSHOUT_SUFFIX`)
BASELINE_METHODS = ("global-translate", "root-translate", "root-rigid", "affine-translate", "rbf-warp")
#: method-name suffix that switches on :func:`push_out`
PUSHOUT_SUFFIX = "+pushout"
#: default distance (m) non-root particles keep from the target body after push-out (paper ε_c)
DEFAULT_CLEARANCE = 5e-4
#: bone whose skin weights define the head region of ``affine-translate``
HEAD_BONE_NAME = "head"
#: skin weight (unitless) of the head bone from which a vertex belongs to the head region
HEAD_WEIGHT_THRESHOLD = 0.5
#: the hair's bounding box is enlarged by this fraction of its extent (half on each side)
BOX_ENLARGEMENT = 0.2
#: at least this padding (m) on each side of the enlarged hair box (flat or tiny hairstyles)
MIN_BOX_PADDING = 1e-3
#: fewest non-coplanar points an affine fit or a thin-plate spline with a linear term needs
MIN_FIT_POINTS = 4
#: a point set counts as spanning 3-D when its smallest centred singular value exceeds this
#: fraction of the largest (unitless)
MIN_SPREAD_RATIO = 1e-6
#: most mesh vertices used as centres of the ``rbf-warp`` thin-plate spline
RBF_MAX_CENTERS = 1500
#: farthest-point sampling of the centres starts from at most this many candidates per centre,
#: drawn at random with :data:`RBF_SEED` (the greedy loop costs centres x candidates)
RBF_CANDIDATES_PER_CENTER = 8
#: seed of that random draw (results are deterministic)
RBF_SEED = 0
#: kernel of the ``rbf-warp`` displacement field
RBF_KERNEL = "thin_plate_spline"
#: particles evaluated per RBF call (bounds the (chunk, centres) kernel matrix: ~50 MB)
RBF_CHUNK_PARTICLES = 4096
#: particles rotated per chunk in ``root-rigid`` (bounds the (chunk, 3, 3) gathered rotations)
ROTATION_CHUNK_PARTICLES = 1 << 18


def parse_method(name: str) -> tuple[str, bool]:
    """Split a method name into the baseline and whether push-out follows.

    Parameters
    ----------
    name : str
        One of :data:`BASELINE_METHODS`, optionally followed by ``"+pushout"``
        (case and surrounding spaces are ignored).

    Returns
    -------
    base : str
        An entry of :data:`BASELINE_METHODS`.
    pushout : bool

    Raises
    ------
    InputError
        ``code="unknown_method"``, listing the valid names.
    """
    if not isinstance(name, str):
        raise InputError(f"method must be a string, got {type(name).__name__}", code="unknown_method")
    base = name.strip().lower()
    pushout = base.endswith(PUSHOUT_SUFFIX)
    if pushout:
        base = base[: -len(PUSHOUT_SUFFIX)].strip()
    if base not in BASELINE_METHODS:
        raise InputError(
            f"unknown baseline method {name!r}; valid methods are {', '.join(BASELINE_METHODS)} "
            f"(each optionally followed by {PUSHOUT_SUFFIX!r})",
            code="unknown_method",
        )
    return base, pushout


def hair_box(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The hair's axis-aligned bounding box enlarged by :data:`BOX_ENLARGEMENT`.

    Parameters
    ----------
    points : (N, 3) float64, N >= 1

    Returns
    -------
    lower, upper : (3,) float64
    """
    lower, upper = points.min(axis=0), points.max(axis=0)
    pad = np.maximum(0.5 * BOX_ENLARGEMENT * (upper - lower), MIN_BOX_PADDING)
    return lower - pad, upper + pad


def in_box(points: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """(N,) bool: which of ``points (N, 3)`` lie inside the box ``[lower, upper]``."""
    return ((points >= lower) & (points <= upper)).all(axis=1)


def spans_3d(points: np.ndarray) -> bool:
    """Whether ``points (K, 3)`` has at least :data:`MIN_FIT_POINTS` points not all coplanar."""
    if len(points) < MIN_FIT_POINTS:
        return False
    singular = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    return bool(singular[0] > 0 and singular[-1] > MIN_SPREAD_RATIO * singular[0])


def head_region(source: Character, hair: Hair) -> np.ndarray:
    """Vertices driving ``affine-translate``.

    The vertices with :data:`HEAD_BONE_NAME` skin weight >= :data:`HEAD_WEIGHT_THRESHOLD`
    if the source is rigged with such a bone; otherwise (or if those do not span 3-D) the
    vertices inside the enlarged hair box; otherwise all vertices.

    Parameters
    ----------
    source : Character
    hair : Hair
        Non-empty.

    Returns
    -------
    vertex_ids : (K,) int64
    """
    candidates = []
    skeleton = source.skeleton
    if skeleton is not None and source.weights is not None:
        names = [name.lower() for name in skeleton.names]
        if HEAD_BONE_NAME in names:
            column = source.weights[:, names.index(HEAD_BONE_NAME)].toarray().ravel()
            candidates.append(np.flatnonzero(column >= HEAD_WEIGHT_THRESHOLD))
    candidates.append(np.flatnonzero(in_box(source.vertices, *hair_box(hair.points))))
    for ids in candidates:
        if spans_3d(source.vertices[ids]):
            return ids
    return np.arange(source.n_vertices, dtype=np.int64)


def fit_affine(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares affine map ``dst ≈ src @ M + c`` (centred for conditioning).

    Parameters
    ----------
    src, dst : (K, 3) float64
        Corresponding points, K >= 4 and not coplanar.

    Returns
    -------
    M : (3, 3) float64
        Acting on row vectors.
    c : (3,) float64
    """
    src_mean, dst_mean = src.mean(axis=0), dst.mean(axis=0)
    M = np.linalg.lstsq(src - src_mean, dst - dst_mean, rcond=None)[0]
    return M, dst_mean - src_mean @ M


def farthest_point_sample(points: np.ndarray, count: int) -> np.ndarray:
    """Greedy farthest-point sampling, deterministic (starts at the point nearest the centroid).

    The loop runs over the ``count`` samples, each step vectorised over all points.

    Parameters
    ----------
    points : (M, 3) float64
    count : int

    Returns
    -------
    ids : (min(M, count),) int64
        Indices into ``points``, in sampling order.
    """
    m = len(points)
    if m <= count:
        return np.arange(m, dtype=np.int64)
    ids = np.empty(count, dtype=np.int64)
    nearest_sq = np.full(m, np.inf)
    offset = points - points.mean(axis=0)
    current = int(np.argmin(np.einsum("ij,ij->i", offset, offset)))
    for k in range(count):
        ids[k] = current
        np.subtract(points, points[current], out=offset)
        np.minimum(nearest_sq, np.einsum("ij,ij->i", offset, offset), out=nearest_sq)
        current = int(np.argmax(nearest_sq))
    return ids


def rbf_centers(source: Character, hair: Hair) -> np.ndarray:
    """Source vertices used as ``rbf-warp`` centres: near the hair, distinct, well spread.

    Vertices inside the enlarged hair box (all vertices if those do not span 3-D), with
    duplicated positions removed, thinned to :data:`RBF_MAX_CENTERS` by farthest-point
    sampling (from a seeded random subset of :data:`RBF_CANDIDATES_PER_CENTER` candidates
    per centre when there are more).

    Parameters
    ----------
    source : Character
    hair : Hair
        Non-empty.

    Returns
    -------
    vertex_ids : (K,) int64
    """
    ids = np.flatnonzero(in_box(source.vertices, *hair_box(hair.points)))
    if not spans_3d(source.vertices[ids]):
        ids = np.arange(source.n_vertices, dtype=np.int64)
    # coincident centres make the interpolation matrix singular (smoothing = 0)
    _, first = np.unique(source.vertices[ids], axis=0, return_index=True)
    ids = ids[np.sort(first)]
    max_candidates = RBF_CANDIDATES_PER_CENTER * RBF_MAX_CENTERS
    if len(ids) > max_candidates:
        rng = np.random.default_rng(RBF_SEED)
        ids = np.sort(rng.choice(ids, max_candidates, replace=False))
    return ids[farthest_point_sample(source.vertices[ids], RBF_MAX_CENTERS)]


def snap_roots(points: np.ndarray, hair: Hair, targets: np.ndarray) -> np.ndarray:
    """Set the root particles of ``points (N, 3)`` to ``targets (S, 3)`` in place; return it."""
    points[hair.roots] = targets
    return points


def _global_translate(source: Character, target: Character, hair: Hair, faces: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Fig. 2b top: every particle moves by the mean root displacement (roots not snapped)."""
    shift = (targets - hair.points[hair.roots]).mean(axis=0)
    return hair.points + shift


def _root_translate(source: Character, target: Character, hair: Hair, faces: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Fig. 2b bottom: each strand moves by its own root displacement."""
    shift = targets - hair.points[hair.roots]
    return snap_roots(hair.points + shift[hair.strand_of], hair, targets)


def _root_rigid(source: Character, target: Character, hair: Hair, faces: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Each strand moves with its root and turns with its root face's frame, ``R = F_t F_s^T``."""
    frames_s, valid_s = face_frames(source.vertices, source.faces, faces)
    frames_t, valid_t = face_frames(target.vertices, target.faces, faces)
    rotation = frames_t @ frames_s.transpose(0, 2, 1)  # (S, 3, 3)
    rotation[~(valid_s & valid_t)] = np.eye(3)
    strand_of = hair.strand_of
    roots = hair.points[hair.roots]
    out = np.empty_like(hair.points)
    for start in range(0, hair.n_particles, ROTATION_CHUNK_PARTICLES):
        chunk = slice(start, start + ROTATION_CHUNK_PARTICLES)
        s = strand_of[chunk]
        out[chunk] = targets[s] + np.einsum("nij,nj->ni", rotation[s], hair.points[chunk] - roots[s])
    return snap_roots(out, hair, targets)


def _affine_translate(source: Character, target: Character, hair: Hair, faces: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Fig. 2c: least-squares affine map of the head region, then per-strand root translation."""
    region = head_region(source, hair)
    M, c = fit_affine(source.vertices[region], target.vertices[region])
    mapped = hair.points @ M + c
    shift = targets - mapped[hair.roots]
    return snap_roots(mapped + shift[hair.strand_of], hair, targets)


def _rbf_warp(source: Character, target: Character, hair: Hair, faces: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Thin-plate-spline warp of space by the body displacement near the hair; roots snapped."""
    centers = rbf_centers(source, hair)
    field = RBFInterpolator(
        source.vertices[centers],
        target.vertices[centers] - source.vertices[centers],
        kernel=RBF_KERNEL,
        smoothing=0.0,
    )
    out = np.empty_like(hair.points)
    for start in range(0, hair.n_particles, RBF_CHUNK_PARTICLES):
        chunk = slice(start, start + RBF_CHUNK_PARTICLES)
        out[chunk] = hair.points[chunk] + field(hair.points[chunk])
    return snap_roots(out, hair, targets)


_METHODS: dict[str, Callable[..., np.ndarray]] = {
    "global-translate": _global_translate,
    "root-translate": _root_translate,
    "root-rigid": _root_rigid,
    "affine-translate": _affine_translate,
    "rbf-warp": _rbf_warp,
}


def retarget_baseline(
    method: str,
    source: Character,
    target: Character,
    hair: Hair,
    *,
    pushout: bool = False,
    clearance: float = DEFAULT_CLEARANCE,
    target_query: MeshQuery | None = None,
) -> Hair:
    """Retarget a hairstyle with one of the naive baselines.

    Parameters
    ----------
    method : str
        One of :data:`BASELINE_METHODS`, optionally with the suffix ``"+pushout"``.
    source, target : Character
        Same topology.
    hair : Hair
        S strands, N particles, made for ``source``.
    pushout : bool
        Follow with :func:`push_out` (also switched on by the method suffix).
    clearance : float
        Meters, for the push-out.
    target_query : MeshQuery, optional
        Over the target mesh, to reuse for the push-out; built when needed otherwise.

    Returns
    -------
    hair : Hair
        Same layout and attributes (thickness, color), new points (N, 3).

    Raises
    ------
    InputError
        Unknown method, negative or non-finite clearance, a ``target_query`` over another mesh.
    TopologyMismatch
        Source and target differ in topology.
    """
    base, suffix_pushout = parse_method(method)
    pushout = bool(pushout) or suffix_pushout
    check_same_topology(source, target)
    if not (np.isfinite(clearance) and clearance >= 0):
        raise InputError(f"clearance must be a finite length >= 0 m, got {clearance!r}", code="bad_option")
    if target_query is not None and target_query.vertices.shape != target.vertices.shape:
        raise InputError(
            f"target_query is over a mesh of {len(target_query.vertices)} vertices, "
            f"the target has {target.n_vertices}",
            code="bad_option",
        )
    if hair.n_strands == 0:
        return hair.with_points(hair.points.copy())
    source_query = MeshQuery(source.vertices, source.faces)
    faces, bary = surface_anchors(source_query, source_query.signed_distance(hair.points[hair.roots]))
    targets = root_targets(target, faces, bary)
    points = _METHODS[base](source, target, hair, faces, targets)
    if pushout:
        query = target_query if target_query is not None else MeshQuery(target.vertices, target.faces)
        points = push_out(points, hair.is_root, query, clearance)
    return hair.with_points(points)
