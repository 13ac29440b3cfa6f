"""Initial transfer, anchoring (paper Sec. 4.2, Eq. 2-3): each particle's local coordinates
relative to a bone and the body, and the same coordinates placed on a target.

Convention: hair particles ``(N, 3) float64`` in meters in the CSR layout of
:mod:`hairport.solver.model.hair`; characters as in :mod:`hairport.solver.model.character`.

Anchoring depends on the source only (:func:`compute_anchors`, part of preprocessing);
placing the anchors on a target (:func:`place_anchors`, :func:`root_targets`) runs per
target, before the smoothing of :mod:`.smoothing`. Roots are anchored by
:func:`surface_anchors`, which the baselines (:mod:`hairport.solver.baselines`) share.

Deviations from the paper's text, on purpose:

* Roots are anchored to their own closest point on the source surface (face and
  barycentric coordinates), so that they land exactly on the target surface; a bone ray
  can hit another part of the body (an ear) before the root.
* The anchor length ``eta`` is signed along the ray, so a particle lying before the hit
  point is reproduced exactly too (reflexive retargeting is exact).
* A particle whose rays all miss or leave every valid region keeps its offset to its
  closest surface point in that face's tangent frame (``fallback``); counted in reports.
* Besides the valid region, Eq. 2's indicator also asks that the hit lie within reach of
  the particle (:data:`.bone_rays.ANCHOR_REACH_FACTOR`); a particle no bone reaches falls back to its
  closest surface point.
* On the target, the ray origin ``o_b`` is the point of the (inner part of the) bone
  closest to the mapped hit ``q_b``, not the point at the source's bone parameter: on the
  source ``p``, ``q_b`` and ``o_b`` are collinear with ``o_b`` the foot of ``p`` (and of
  ``q_b``) on the bone, so choosing the foot again on the target makes anchoring exactly
  invertible for a particle that keeps its bone. Measured on an A -> B -> A round trip of
  anchoring alone (average female and male): 0.12 mm / 0.012 rad instead of 0.96 mm /
  0.046 rad.
* A bone's ray must leave the body at its hit (the hit face looks along the ray): a ray
  from a joint lying outside the body (MakeHuman's head tail sits on the scalp) enters
  the body first, which is no anchor.
* Sources without a rig (most real head meshes) are anchored by the body surface instead
  (``anchoring="surface"``, the closest-triangle anchoring the paper's Sec. 7.3.2 discusses):
  every particle keeps its offset to its closest surface point in that face's tangent frame,
  the bones' fallback for every particle; about as good as the bones on the MakeHuman pairs
  (docs/method.md). ``auto`` takes the bones when the source has a skeleton with skin
  weights, else the surface.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hairport.solver.mesh.query import MeshQuery, SignedDistance
from hairport.solver.mesh.triangles import barycentric_coordinates, face_frames, interpolate_barycentric
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError
from hairport.solver.model.frame import AUTO
from hairport.solver.transfer.bone_rays import MIN_RAY_LENGTH, BoneRays, anchor_by_bones, bone_rays
from hairport.solver.transfer.root_shell import snap_roots_to_skin

#: bones hair can rest on, in the MakeHuman game-engine rig's names
HAIR_BONES = ("head", "neck_01", "spine_03", "spine_02", "clavicle_l", "clavicle_r", "upperarm_l", "upperarm_r")
#: how particles are anchored: by the bones' rays (Eq. 2), by their closest surface point, or
#: by the bones when the source has a rig and by the surface when it has none
ANCHOR_BY_BONES = "bones"
ANCHOR_BY_SURFACE = "surface"
ANCHOR_AUTO = AUTO
ANCHORINGS = (ANCHOR_AUTO, ANCHOR_BY_BONES, ANCHOR_BY_SURFACE)
#: Eq. 2's sigma: penalty on rays running along their bone (unitless)
ANCHOR_SIGMA = 100.0
#: a face belongs to the valid region of a bone where its mean skin weight exceeds this
VALID_REGION_WEIGHT = 0.05

#: particles anchored at a time by :func:`compute_anchors` (bounds its temporaries to ~100 MB)
ANCHOR_CHUNK = 1 << 17
#: ray origins stay on the part of a bone at least this deep (m) inside the body
ANCHOR_BONE_DEPTH = 0.02
#: samples along a bone when finding that part
BONE_DEPTH_SAMPLES = 64


#: storage of the anchors' bone and face indices (a skeleton has far fewer than 2^15 bones, a
#: body far fewer than 2^31 faces): indices only index, the math is float64
BONE_INDEX_DTYPE = np.int16
FACE_INDEX_DTYPE = np.int32


@dataclass(frozen=True, eq=False)
class Anchors:
    """Per-particle local coordinates relative to the body (Eq. 2-3).

    Attributes
    ----------
    bone : (N,) int16
        Anchor bone (skeleton index); ``-1`` for roots and fallback particles.
    face : (N,) int32
        Face hit by the ray (roots and fallbacks: face of the closest point).
    barycentric : (N, 3) float64
    eta : (N,) float64
        Signed distance from the hit point to the particle along the ray (m).
    frame_offset : (F, 3) float64
        One row per fallback particle, in particle order (``F = fallback.sum()``): its offset
        to the closest point in the face frame (normal, edge, binormal).
    fallback : (N,) bool
    """

    bone: np.ndarray
    face: np.ndarray
    barycentric: np.ndarray
    eta: np.ndarray
    frame_offset: np.ndarray
    fallback: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "bone", np.asarray(self.bone, dtype=BONE_INDEX_DTYPE))
        object.__setattr__(self, "face", np.asarray(self.face, dtype=FACE_INDEX_DTYPE))
        object.__setattr__(self, "fallback", np.asarray(self.fallback, dtype=bool))
        offsets = np.asarray(self.frame_offset, dtype=np.float64).reshape(-1, 3)
        if len(offsets) != int(self.fallback.sum()):
            raise ValueError(f"frame_offset has {len(offsets)} rows for {int(self.fallback.sum())} fallback particles")
        object.__setattr__(self, "frame_offset", offsets)


def hair_bone_indices(character: Character) -> np.ndarray:
    """Indices of the bones hair can be anchored to; all bones if none of :data:`HAIR_BONES` exist.

    Returns
    -------
    bones : (B',) int64
    """
    skeleton = character.skeleton
    if skeleton is None:
        raise InputError("character has no skeleton; anchoring needs one", character.name, "no_skeleton")
    found = [skeleton.names.index(b) for b in HAIR_BONES if b in skeleton.names]
    return np.array(found if found else range(skeleton.n_bones), dtype=np.int64)


def valid_face_mask(character: Character, bones: np.ndarray) -> np.ndarray:
    """Valid region Lambda_b of each bone from clipped skin weights.

    Returns
    -------
    mask : (F, B') bool
        ``mask[f, j]`` is True where face ``f`` belongs to the region of ``bones[j]``.
    """
    if character.weights is None:
        raise InputError("character has no skin weights; anchoring needs them", character.name, "no_skeleton")
    weights = character.weights[:, bones].toarray()
    face_weight = weights[character.faces].mean(axis=1)
    return face_weight > VALID_REGION_WEIGHT


def resolve_anchoring(anchoring: str, character: Character) -> str:
    """The anchoring a source gets: :data:`ANCHOR_BY_BONES` or :data:`ANCHOR_BY_SURFACE`.

    Parameters
    ----------
    anchoring : str
        One of :data:`ANCHORINGS`; ``auto`` takes the bones when ``character`` has a
        skeleton with skin weights, else the surface.
    character : Character
        The source.

    Raises
    ------
    InputError
        ``bad_option`` for an unknown name; ``no_skeleton`` for ``bones`` on a character
        without a skeleton with skin weights.
    """
    if anchoring not in ANCHORINGS:
        raise InputError(f"unknown anchoring {anchoring!r}; expected one of {', '.join(ANCHORINGS)}", code="bad_option")
    rigged = character.skeleton is not None and character.weights is not None
    if anchoring == ANCHOR_AUTO:
        return ANCHOR_BY_BONES if rigged else ANCHOR_BY_SURFACE
    if anchoring == ANCHOR_BY_BONES and not rigged:
        raise InputError(
            "anchoring by bones needs a source character with a skeleton and skin weights; "
            "give one (a skeleton JSON or a glTF skin) or anchor by the surface (anchoring surface or auto)",
            character.name, "no_skeleton",
        )
    return anchoring


def inner_bone_segments(heads: np.ndarray, tails: np.ndarray, query: MeshQuery) -> tuple[np.ndarray, np.ndarray]:
    """Part of each bone lying at least :data:`ANCHOR_BONE_DEPTH` inside the body.

    Rays cast from a joint on or outside the skin (MakeHuman's head tail sits on the scalp)
    graze the surface and make poor anchors, so ray origins are kept to this part.

    Parameters
    ----------
    heads, tails : (B, 3) float64
    query : MeshQuery
        The body.

    Returns
    -------
    inner_heads, inner_tails : (B, 3) float64
        Ends of the inner part; both the deepest sample where no sample is deep enough.
    """
    t = np.linspace(0.0, 1.0, BONE_DEPTH_SAMPLES)
    samples = heads[:, None, :] + t[None, :, None] * (tails - heads)[:, None, :]
    depth = -query.signed_distance(samples.reshape(-1, 3)).distance.reshape(len(heads), -1)
    deep = depth >= ANCHOR_BONE_DEPTH
    deepest = t[np.argmax(depth, axis=1)]
    lo = np.where(deep.any(axis=1), t[np.argmax(deep, axis=1)], deepest)
    hi = np.where(deep.any(axis=1), t[len(t) - 1 - np.argmax(deep[:, ::-1], axis=1)], deepest)
    axis = tails - heads
    return heads + lo[:, None] * axis, heads + hi[:, None] * axis


def surface_anchors(query: MeshQuery, surface: SignedDistance) -> tuple[np.ndarray, np.ndarray]:
    """Anchor points at their closest point on the mesh: its face and barycentric coordinates.

    The anchor of every root (so that roots land exactly on the target surface, Eq. 12) and
    of every fallback particle.

    Parameters
    ----------
    query : MeshQuery
        Over the source mesh.
    surface : SignedDistance
        ``query.signed_distance`` of the K points to anchor.

    Returns
    -------
    faces : (K,) int64
        Face holding each closest point.
    barycentric : (K, 3) float64
        Of the closest point in that face.
    """
    triangles = query.vertices[query.faces[surface.faces]]
    return surface.faces, barycentric_coordinates(surface.closest, triangles)


def root_targets(target: Character, faces: np.ndarray, barycentric: np.ndarray) -> np.ndarray:
    """Where each root belongs on the target: its anchor (same face, same barycentric coordinates) there.

    Parameters
    ----------
    target : Character
        Same topology as the source the anchors were taken on.
    faces : (S,) int64
    barycentric : (S, 3) float64
        Root anchors, from :func:`surface_anchors` (or an :class:`Anchors`' rows of the roots).

    Returns
    -------
    targets : (S, 3) float64
    """
    return interpolate_barycentric(target.vertices, target.faces, faces, barycentric)


def compute_anchors(
    source: Character,
    points: np.ndarray,
    is_root: np.ndarray,
    query: MeshQuery | None = None,
    sigma: float = ANCHOR_SIGMA,
    anchoring: str = ANCHOR_BY_BONES,
    chunk: int = ANCHOR_CHUNK,
) -> Anchors:
    """Choose an anchor bone per particle and record its local coordinates (Eq. 2).

    Parameters
    ----------
    source : Character
        The source character; rigged (skeleton and skin weights) for ``anchoring="bones"``.
    points : (N, 3) float64
        Source hair particles.
    is_root : (N,) bool
    query : MeshQuery, optional
        Prebuilt query structure of the source mesh.
    sigma : float
        Eq. 2's sigma.
    anchoring : str
        :data:`ANCHOR_BY_BONES` (Eq. 2, closest surface point where no bone reaches) or
        :data:`ANCHOR_BY_SURFACE` (every particle by its closest surface point: ``fallback``
        everywhere but the roots).
    chunk : int
        Particles anchored at a time (bounds the temporaries; the result does not depend on it).

    Returns
    -------
    anchors : Anchors
    """
    if anchoring not in (ANCHOR_BY_BONES, ANCHOR_BY_SURFACE):
        raise InputError(f"unknown anchoring {anchoring!r}; expected {ANCHOR_BY_BONES} or {ANCHOR_BY_SURFACE}",
                         code="bad_option")
    query = query or MeshQuery(source.vertices, source.faces)
    is_root = np.asarray(is_root, dtype=bool)
    n = len(points)
    best = {
        "bone": np.full(n, -1, BONE_INDEX_DTYPE),
        "face": np.full(n, -1, FACE_INDEX_DTYPE),
        "barycentric": np.zeros((n, 3)),
        "eta": np.zeros(n),
    }
    rays = _source_bone_rays(source, query) if anchoring == ANCHOR_BY_BONES else None
    fallback = np.zeros(n, dtype=bool)
    # one closest-point query per particle serves the reach test of the bones and the anchors
    # of roots and fallback particles: only those rows of it are kept
    kept: list[np.ndarray] = []
    kept_surface: list[SignedDistance] = []
    for start in range(0, n, max(1, int(chunk))):
        part = slice(start, min(n, start + max(1, int(chunk))))
        surface = query.signed_distance(points[part])
        if rays is None:
            reached = np.zeros(part.stop - start, dtype=bool)
        else:
            reached = anchor_by_bones(rays, query, points[part], is_root[part], surface.distance, sigma,
                                      {name: values[part] for name, values in best.items()})
        fallback[part] = ~is_root[part] & ~reached
        rows = np.flatnonzero(is_root[part] | fallback[part])
        kept.append(start + rows)
        kept_surface.append(surface.take(rows))
    idx = np.concatenate(kept) if kept else np.zeros(0, np.int64)
    if len(idx) == 0:
        return Anchors(frame_offset=np.zeros((0, 3)), fallback=fallback, **best)
    surface = SignedDistance(*(np.concatenate([getattr(s, name) for s in kept_surface])
                               for name in ("distance", "closest", "normal", "faces")))
    # roots closer to an eye, a lash or a stray face than to the skin are anchored on the skin
    surface, _ = snap_roots_to_skin(query, points[idx], surface, is_root[idx])
    faces, barycentric = surface_anchors(query, surface)
    best["face"][idx] = faces
    best["barycentric"][idx] = barycentric
    best["bone"][idx] = -1
    # the frame offsets of the fallback particles (the roots lie on their faces: none)
    moved = fallback[idx]
    faces, idx = faces[moved], idx[moved]
    frames, _ = face_frames(source.vertices, source.faces, faces)
    offsets = points[idx] - interpolate_barycentric(source.vertices, source.faces, faces, best["barycentric"][idx])
    frame_offset = np.einsum("nji,nj->ni", frames, offsets)
    return Anchors(frame_offset=frame_offset, fallback=fallback, **best)


def _source_bone_rays(source: Character, query: MeshQuery) -> BoneRays:
    """:class:`~.bone_rays.BoneRays` of the source's hair bones."""
    skeleton = source.skeleton
    bones = hair_bone_indices(source)
    valid = valid_face_mask(source, bones)
    inner_heads, inner_tails = inner_bone_segments(skeleton.heads[bones], skeleton.tails[bones], query)
    return bone_rays(source.vertices, source.faces, bones, valid, skeleton.heads[bones], skeleton.tails[bones],
                     inner_heads, inner_tails)


def _closest_on_bones(points: np.ndarray, heads: np.ndarray, tails: np.ndarray) -> np.ndarray:
    """Closest point on each particle's own bone segment: ``points, heads, tails (K, 3)``."""
    axis = tails - heads
    t = np.einsum("ij,ij->i", points - heads, axis) / np.maximum(np.einsum("ij,ij->i", axis, axis), MIN_RAY_LENGTH**2)
    return heads + np.clip(t, 0.0, 1.0)[:, None] * axis


def place_anchors(anchors: Anchors, target: Character, query: MeshQuery | None = None,
                  chunk: int = ANCHOR_CHUNK) -> np.ndarray:
    """Apply the local coordinates on the target (Eq. 3).

    Parameters
    ----------
    anchors : Anchors
    target : Character
        Same topology as the source; its skeleton in the source's bone order where any
        particle is anchored by a bone.
    query : MeshQuery, optional
        Prebuilt query structure of the target mesh.
    chunk : int
        Particles placed at a time (bounds the temporaries; the result does not depend on it).

    Returns
    -------
    points : (N, 3) float64
        The anchored particles ``p~``.
    """
    n = len(anchors.face)
    points = np.empty((n, 3))
    used = np.unique(anchors.bone[anchors.bone >= 0])
    if len(used):
        skeleton = target.skeleton
        if skeleton is None:
            raise InputError("the hairstyle is anchored by bones, and the target has no skeleton",
                             target.name, "no_skeleton")
        query = query or MeshQuery(target.vertices, target.faces)
        inner_heads = np.zeros((skeleton.n_bones, 3))
        inner_tails = np.zeros((skeleton.n_bones, 3))
        inner_heads[used], inner_tails[used] = inner_bone_segments(skeleton.heads[used], skeleton.tails[used], query)
    fallback_row = 0
    step = max(1, int(chunk))
    for start in range(0, n, step):
        part = slice(start, min(n, start + step))
        face, bone, fallback = anchors.face[part], anchors.bone[part], anchors.fallback[part]
        q = interpolate_barycentric(target.vertices, target.faces, face, anchors.barycentric[part])
        placed = points[part]
        placed[:] = q
        ray_based = np.flatnonzero(bone >= 0)
        if len(ray_based):
            on = bone[ray_based]
            origin = _closest_on_bones(q[ray_based], inner_heads[on], inner_tails[on])
            direction = q[ray_based] - origin
            direction /= np.maximum(np.linalg.norm(direction, axis=1, keepdims=True), MIN_RAY_LENGTH)
            placed[ray_based] += anchors.eta[part][ray_based, None] * direction
        rows = np.flatnonzero(fallback)
        if len(rows):
            frames, _ = face_frames(target.vertices, target.faces, face[rows])
            offsets = anchors.frame_offset[fallback_row : fallback_row + len(rows)]
            placed[rows] += np.einsum("nij,nj->ni", frames, offsets)
            fallback_row += len(rows)
    return points
