"""The wrap's start: a similarity (uniform scale, rotation, translation) of the source onto the target.

Both bodies are in hairport's canonical frame (Y up, the face toward +Z), so the start is
mostly a scale and a translation. Without landmarks it comes from the two heads
(:func:`head_similarity`: the rigless head frame of :func:`~hairport.solver.body.head_frame.mesh_head_frame`
on both meshes, the scale from the skulls' depth and width); with three or more landmark
pairs from them (:func:`fit_similarity`, Umeyama 1991). Either is then refined by a few
iterations of similarity ICP on the source's head (:func:`refine_similarity`), with the
wrap's correspondence rejections, so that a body of another height or build is aligned at
the head, where the hair is, and not on average over the body.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hairport.solver.body.head_frame import HeadFrame
from hairport.solver.wrap.options import WrapOptions
from hairport.solver.wrap.surface import TargetSurface, vertex_normals


@dataclass(frozen=True)
class Similarity:
    """``p -> scale * R p + translation``.

    Attributes
    ----------
    scale : float
    rotation : (3, 3) float64
    translation : (3,) float64
        Meters.
    """

    scale: float
    rotation: np.ndarray
    translation: np.ndarray

    def apply(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) the moved ``points (N, 3)``."""
        return self.scale * np.asarray(points) @ self.rotation.T + self.translation

    def then(self, other: "Similarity") -> "Similarity":
        """This similarity followed by ``other``."""
        return Similarity(other.scale * self.scale, other.rotation @ self.rotation, other.apply(self.translation))

    @property
    def angle_deg(self) -> float:
        """The rotation's angle (degrees)."""
        return float(np.degrees(np.arccos(np.clip((np.trace(self.rotation) - 1.0) / 2.0, -1.0, 1.0))))


IDENTITY = Similarity(1.0, np.eye(3), np.zeros(3))


def head_similarity(source: HeadFrame, target: HeadFrame) -> Similarity:
    """The similarity that puts the source's head frame on the target's: scale from the skulls'
    depth and width (their geometric mean ratio), the source head joint on the target's, no rotation.

    Parameters
    ----------
    source, target : HeadFrame
        Of the two meshes (the rigless estimate on both, so that both are read alike).
    """
    depth = (target.front - target.back) / (source.front - source.back)
    width = target.half_width / source.half_width
    scale = float(np.sqrt(depth * width))
    return Similarity(scale, np.eye(3), target.origin - scale * source.origin)


def fit_similarity(source: np.ndarray, target: np.ndarray, weights: np.ndarray | None = None,
                   rotate: bool = True) -> Similarity:
    """The least-squares similarity taking ``source (N, 3)`` to ``target (N, 3)`` (Umeyama 1991).

    Parameters
    ----------
    weights : (N,) float64, optional
        Per pair; by default all 1.
    rotate : bool
        False: scale and translation only.
    """
    w = np.ones(len(source)) if weights is None else np.asarray(weights, dtype=np.float64)
    w = w / w.sum()
    mu_s, mu_t = w @ source, w @ target
    s, t = source - mu_s, target - mu_t
    variance = float(w @ np.einsum("ij,ij->i", s, s))
    if rotate:
        u, sigma, vt = np.linalg.svd((t * w[:, None]).T @ s)
        d = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt)) or 1.0])
        rotation = u @ d @ vt
        scale = float(np.trace(np.diag(sigma) @ d) / variance)
    else:
        rotation = np.eye(3)
        scale = float(w @ np.einsum("ij,ij->i", t, s) / variance)
    return Similarity(scale, rotation, mu_t - scale * rotation @ mu_s)


def refine_similarity(start: Similarity, points: np.ndarray, triangles: np.ndarray, surface: TargetSurface,
                      max_distance: float, min_cosine: float, iterations: int, tolerance: float) -> Similarity:
    """Similarity ICP of a source patch on the target, from ``start``.

    Parameters
    ----------
    points : (n, 3) float64
        The source patch's vertices (m), before ``start``.
    triangles : (t, 3) int64
        Its faces, local ids (for the normals of the rejection test).
    surface : TargetSurface
    max_distance, min_cosine : float
        The rejections of :meth:`TargetSurface.match` (m; cosine).
    iterations : int
        At most this many steps.
    tolerance : float
        Stop when no point moves farther than this in a step (m).

    Returns
    -------
    similarity : Similarity
        The start when fewer than 3 correspondences are accepted at some step.
    """
    current, hint = start, None
    for _ in range(iterations):
        moved = current.apply(points)
        match = surface.match(moved, vertex_normals(moved, triangles), max_distance, min_cosine, hint)
        hint = match.faces
        if np.count_nonzero(match.accepted) < 3:
            break
        step = fit_similarity(moved[match.accepted], match.closest[match.accepted])
        current = current.then(step)
        if np.abs(step.apply(moved) - moved).max() < tolerance:
            break
    return current


def start_similarity(source_vertices: np.ndarray, head_patch: tuple[np.ndarray, np.ndarray], frames: tuple,
                     surface: TargetSurface, landmarks: dict, options: WrapOptions) -> Similarity:
    """The start of the wrap: from three or more landmark pairs, else from the two head frames,
    then refined by similarity ICP of the source's head patch.

    Parameters
    ----------
    source_vertices : (V, 3) float64
        Meters.
    head_patch : ((h,) int64, (t, 3) int64)
        Source ids of the head patch's vertices and its faces in local ids.
    frames : (HeadFrame, HeadFrame)
        Of the source and of the target.
    surface : TargetSurface
    landmarks : dict of str to ((3,), (3,))
        Source and target point per name (may be empty).
    options : WrapOptions
    """
    if len(landmarks) >= 3:
        pairs = np.array([[np.asarray(s, float), np.asarray(t, float)] for s, t in landmarks.values()])
        start = fit_similarity(pairs[:, 0], pairs[:, 1])
    else:
        start = head_similarity(*frames)
    ids, triangles = head_patch
    if len(triangles) == 0 or options.start_iterations == 0:
        return start
    min_cosine = float(np.cos(np.radians(options.max_normal_angle_deg)))
    return refine_similarity(start, source_vertices[ids], triangles, surface, options.max_distance_m, min_cosine,
                             options.start_iterations, options.tolerance_m)
