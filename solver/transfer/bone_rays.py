"""Eq. 2's choice of anchor bone: per particle, the bone whose ray scores best, casting only
the rays that can still win.

A particle ``p`` and a hair bone ``b`` give a ray from ``o_b``, the closest point of the
bone's inner part (:func:`~hairport.solver.transfer.anchors.inner_bone_segments`), through
``p``. It counts (Eq. 2's indicator) when its first hit ``q`` on the body lies in the bone's
valid region, leaves the body there, and lies within reach of ``p``
(``|eta| <= ANCHOR_REACH_FACTOR |d(p)| + ANCHOR_REACH_SLACK``, ``d`` the distance to the
body); it scores ``|eta| exp(sigma cos^2)``, ``eta`` the signed distance from ``q`` to ``p``
along the ray and ``cos`` the cosine between the ray and the bone. The lowest score wins
(ties: the lower bone index).

Casting every bone's ray for every particle (:func:`anchor_by_bones_exhaustive`, the
reference) is what preprocessing spent most of its time on. Without casting, a bone's
score is bounded below: the hit is a point of the body, so ``|eta| = |p - q| >= |d(p)|``,
and a point of the bone's valid region, so ``|eta|`` is at least the distance from ``p`` to
that region's bounding box; ``cos`` needs no ray. A bone whose box lies beyond the reach
cannot count at all. :func:`anchor_by_bones` tries each particle's bones in the order of
these bounds and casts a bone's ray only while its bound does not exceed the best score
found so far: the same winner, with ~1.35 rays per particle instead of 8 on the MakeHuman
"long" groom (``bench/preprocess.py``).

Convention: particles ``(N, 3) float64`` in meters; the results go into caller-owned arrays
(``best``: ``bone``, ``face``, ``barycentric``, ``eta``), rows of the particles some bone
reaches.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hairport.solver.jit import parallel_kernel, prange, warms
from hairport.solver.mesh.polyline import closest_points_on_segments
from hairport.solver.mesh.query import MeshQuery

#: a bone whose ray meets the body much farther from the particle than the body's nearest point
#: (|eta| > factor * distance + slack) is not a candidate: a ray from a clavicle can hit its
#: valid shoulder region and travel 10+ cm on to a strand under the chin, and a lever that
#: long turns small body changes into large hair motion
ANCHOR_REACH_FACTOR = 2.0
ANCHOR_REACH_SLACK = 0.01
#: rays shorter than this (m) have no direction
MIN_RAY_LENGTH = 1e-9
#: the lower bounds of the pruned search are lowered by this much (m) and by this fraction
#: before they are compared: far above the rounding of distances and scores (~1e-16 m on a
#: body of a few meters), so a bound never prunes a ray that would have won
BOUND_SLACK = 1e-9
BOUND_RELATIVE_SLACK = 1e-9


@dataclass(frozen=True, eq=False)
class BoneRays:
    """What Eq. 2's search needs of the source body and its hair bones, built once (:func:`bone_rays`).

    Attributes
    ----------
    bones : (B,) int64
        Skeleton index of each hair bone.
    valid : (F, B) bool
        Faces of each bone's valid region.
    face_normals : (F, 3) float64
        Unnormalised face normals (a ray leaves the body where it runs along the normal).
    inner_heads, inner_tails : (B, 3) float64
        The bones' inner parts, where the rays start.
    axes : (B, 3) float64
        Unit bone directions.
    region_lower, region_upper : (B, 3) float64
        Bounding box of each valid region (``+inf`` / ``-inf`` for an empty region).
    """

    bones: np.ndarray
    valid: np.ndarray
    face_normals: np.ndarray
    inner_heads: np.ndarray
    inner_tails: np.ndarray
    axes: np.ndarray
    region_lower: np.ndarray
    region_upper: np.ndarray


def bone_rays(vertices: np.ndarray, faces: np.ndarray, bones: np.ndarray, valid: np.ndarray, heads: np.ndarray,
              tails: np.ndarray, inner_heads: np.ndarray, inner_tails: np.ndarray) -> BoneRays:
    """Assemble :class:`BoneRays`.

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    bones : (B,) int64
    valid : (F, B) bool
    heads, tails : (B, 3) float64
        The bones' ends (their direction).
    inner_heads, inner_tails : (B, 3) float64
        Where the rays start.
    """
    corners = vertices[faces]
    face_normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    axes = tails - heads
    axes /= np.maximum(np.linalg.norm(axes, axis=1, keepdims=True), MIN_RAY_LENGTH)
    lower = np.full((len(bones), 3), np.inf)
    upper = np.full((len(bones), 3), -np.inf)
    for j in range(len(bones)):  # a handful of bones
        region = corners[valid[:, j]].reshape(-1, 3)
        if len(region):
            lower[j], upper[j] = region.min(axis=0), region.max(axis=0)
    return BoneRays(np.asarray(bones, dtype=np.int64), valid, face_normals, inner_heads, inner_tails, axes, lower,
                    upper)


def _rays_of_bone(rays: BoneRays, j: int, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rays of bone column ``j`` through ``points (K, 3)``: origins, rays (unnormalised), lengths, cosines."""
    _, origin = closest_points_on_segments(points, rays.inner_heads[j : j + 1], rays.inner_tails[j : j + 1])
    origin = origin[:, 0]
    ray = points - origin
    length = np.linalg.norm(ray, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        cosine = (ray / length[:, None]) @ rays.axes[j]
    return origin, ray, length, cosine


def _scores(rays: BoneRays, j: int, query: MeshQuery, points: np.ndarray, origin: np.ndarray, ray: np.ndarray,
            length: np.ndarray, cosine: np.ndarray, reach: np.ndarray, sigma: float):
    """Cast bone column ``j``'s rays (all of length > MIN_RAY_LENGTH) and score them (``inf``: no anchor).

    Returns
    -------
    score : (K,) float64
    hits : RayHits
    eta : (K,) float64
    """
    hits = query.first_hits(origin, ray)
    hit_faces = np.where(hits.hit, hits.faces, 0)
    leaving = np.einsum("ij,ij->i", rays.face_normals[hit_faces], ray) > 0.0
    ok = hits.hit & rays.valid[hit_faces, j] & leaving
    unit = ray / length[:, None]
    eta = np.einsum("ij,ij->i", points - hits.points, unit)
    score = np.where(ok, np.abs(eta) * np.exp(sigma * cosine**2), np.inf)
    score = np.where(np.abs(eta) <= reach, score, np.inf)
    return score, hits, eta


def _take(best: dict[str, np.ndarray], rows: np.ndarray, bone: int, hits, eta: np.ndarray, taken: np.ndarray) -> None:
    best["bone"][rows] = bone
    best["face"][rows] = hits.faces[taken]
    best["barycentric"][rows] = hits.barycentric[taken]
    best["eta"][rows] = eta[taken]


def _reach(distance: np.ndarray) -> np.ndarray:
    return ANCHOR_REACH_FACTOR * np.abs(distance) + ANCHOR_REACH_SLACK


def anchor_by_bones(rays: BoneRays, query: MeshQuery, points: np.ndarray, is_root: np.ndarray, distance: np.ndarray,
                    sigma: float, best: dict[str, np.ndarray]) -> np.ndarray:
    """Eq. 2 over the hair bones by the pruned search (module docstring).

    Parameters
    ----------
    rays : BoneRays
    query : MeshQuery
        The source body.
    points : (N, 3) float64
    is_root : (N,) bool
        Roots get no bone.
    distance : (N,) float64
        Signed distance of each particle to the body (``query.signed_distance``).
    sigma : float
        Eq. 2's sigma.
    best : dict of str -> array
        ``bone (N,)``, ``face (N,)``, ``barycentric (N, 3)``, ``eta (N,)``: written where a
        bone reaches the particle, untouched elsewhere.

    Returns
    -------
    reached : (N,) bool
        The particles some bone reaches; equal to :func:`anchor_by_bones_exhaustive`'s, as
        is everything written into ``best``.
    """
    free = np.flatnonzero(~np.asarray(is_root, dtype=bool))
    reached = np.zeros(len(points), dtype=bool)
    n_bones = len(rays.bones)
    if len(free) == 0 or n_bones == 0:
        return reached
    free_points = np.ascontiguousarray(points[free], dtype=np.float64)
    reach = _reach(distance[free])
    bound = score_bounds(rays, free_points, np.abs(distance[free]), reach, sigma)
    order = np.empty(bound.shape, dtype=np.int8)  # each particle's bone columns by ascending bound
    _sort_rows(bound, order)
    best_score = np.full(len(free), np.inf)
    winner = np.full(len(free), n_bones, dtype=np.int64)  # bone column of the best score so far
    for rank in range(n_bones):
        column = order[:, rank]
        lower = bound[:, rank]
        cast = np.flatnonzero(np.isfinite(lower) & (lower <= best_score))
        if len(cast) == 0:
            break
        for j in np.unique(column[cast]):
            rows = cast[column[cast] == j]
            origin, ray, length, cosine = _rays_of_bone(rays, j, free_points[rows])
            usable = length > MIN_RAY_LENGTH  # as the reference decides it (the bound allowed for rounding)
            rows, origin, ray, length, cosine = rows[usable], origin[usable], ray[usable], length[usable], cosine[usable]
            score, hits, eta = _scores(rays, j, query, free_points[rows], origin, ray, length, cosine, reach[rows],
                                       sigma)
            better = np.isfinite(score) & (
                (score < best_score[rows]) | ((score == best_score[rows]) & (j < winner[rows]))
            )
            taken = rows[better]
            best_score[taken] = score[better]
            winner[taken] = j
            _take(best, free[taken], int(rays.bones[j]), hits, eta, better)
    reached[free] = np.isfinite(best_score)
    return reached


def score_bounds(rays: BoneRays, points: np.ndarray, near: np.ndarray, reach: np.ndarray, sigma: float) -> np.ndarray:
    """Lower bounds of every bone's Eq. 2 score, without casting (compiled; :func:`score_bounds_reference`).

    Parameters
    ----------
    rays : BoneRays
    points : (K, 3) float64
        Non-root particles.
    near : (K,) float64
        Their distance to the body (m).
    reach : (K,) float64
        How far from each particle a hit may lie (m).
    sigma : float

    Returns
    -------
    bound : (K, B) float64
        At most the score bone column ``j``'s ray would get (lowered by :data:`BOUND_SLACK`
        and :data:`BOUND_RELATIVE_SLACK`); ``inf`` where the ray has no direction or the
        bone's valid region lies out of reach.
    """
    bound = np.empty((len(points), len(rays.bones)))
    _score_bounds_kernel(np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(near, dtype=np.float64),
                         np.ascontiguousarray(reach, dtype=np.float64), rays.inner_heads, rays.inner_tails, rays.axes,
                         rays.region_lower, rays.region_upper, float(sigma), bound)
    return bound


def score_bounds_reference(rays: BoneRays, points: np.ndarray, near: np.ndarray, reach: np.ndarray,
                           sigma: float) -> np.ndarray:
    """:func:`score_bounds` in numpy, bone by bone (the reference the kernel is tested against)."""
    bound = np.empty((len(points), len(rays.bones)))
    for j in range(len(rays.bones)):
        _, _, length, cosine = _rays_of_bone(rays, j, points)
        outside = np.maximum(rays.region_lower[j] - points, 0.0) + np.maximum(points - rays.region_upper[j], 0.0)
        gap = np.linalg.norm(outside, axis=1)
        candidate = (length > MIN_RAY_LENGTH * (1.0 - BOUND_RELATIVE_SLACK)) & (gap - BOUND_SLACK <= reach)
        nearest_hit = np.maximum(np.maximum(near, gap) - BOUND_SLACK, 0.0)
        with np.errstate(invalid="ignore"):
            bound[:, j] = np.where(candidate, nearest_hit * np.exp(sigma * cosine**2) * (1.0 - BOUND_RELATIVE_SLACK),
                                   np.inf)
    return bound


@parallel_kernel
def _score_bounds_kernel(points, near, reach, inner_heads, inner_tails, axes, region_lower, region_upper, sigma, bound):
    tiny = np.finfo(np.float64).tiny
    for i in prange(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        for j in range(axes.shape[0]):
            hx, hy, hz = inner_heads[j, 0], inner_heads[j, 1], inner_heads[j, 2]
            ax, ay, az = inner_tails[j, 0] - hx, inner_tails[j, 1] - hy, inner_tails[j, 2] - hz
            t = ((px - hx) * ax + (py - hy) * ay + (pz - hz) * az) / max(ax * ax + ay * ay + az * az, tiny)
            t = min(max(t, 0.0), 1.0)
            rx, ry, rz = px - (hx + t * ax), py - (hy + t * ay), pz - (hz + t * az)
            length = np.sqrt(rx * rx + ry * ry + rz * rz)
            gx = max(region_lower[j, 0] - px, 0.0) + max(px - region_upper[j, 0], 0.0)
            gy = max(region_lower[j, 1] - py, 0.0) + max(py - region_upper[j, 1], 0.0)
            gz = max(region_lower[j, 2] - pz, 0.0) + max(pz - region_upper[j, 2], 0.0)
            gap = np.sqrt(gx * gx + gy * gy + gz * gz)
            if length > MIN_RAY_LENGTH * (1.0 - BOUND_RELATIVE_SLACK) and gap - BOUND_SLACK <= reach[i]:
                cosine = (rx * axes[j, 0] + ry * axes[j, 1] + rz * axes[j, 2]) / length
                nearest_hit = max(max(near[i], gap) - BOUND_SLACK, 0.0)
                bound[i, j] = nearest_hit * np.exp(sigma * cosine * cosine) * (1.0 - BOUND_RELATIVE_SLACK)
            else:
                bound[i, j] = np.inf


@parallel_kernel
def _sort_rows(values, order):
    """Sort each row of ``values (K, B)`` in place (ascending, stable) and write where each entry came from
    into ``order (K, B)``: B is a handful of bones, so an insertion sort per row."""
    for i in prange(values.shape[0]):
        for j in range(values.shape[1]):
            order[i, j] = j
        for j in range(1, values.shape[1]):
            value, origin = values[i, j], order[i, j]
            k = j - 1
            while k >= 0 and values[i, k] > value:
                values[i, k + 1], order[i, k + 1] = values[i, k], order[i, k]
                k -= 1
            values[i, k + 1], order[i, k + 1] = value, origin


@warms
def _warm() -> None:
    one = np.zeros((1, 3))
    _score_bounds_kernel(np.ones((2, 3)), np.ones(2), np.ones(2), one, one + 1.0, one + 1.0, one, one + 1.0, 100.0,
                         np.empty((2, 1)))
    _sort_rows(np.array([[2.0, 1.0]]), np.empty((1, 2), dtype=np.int8))


def anchor_by_bones_exhaustive(rays: BoneRays, query: MeshQuery, points: np.ndarray, is_root: np.ndarray,
                               distance: np.ndarray, sigma: float, best: dict[str, np.ndarray]) -> np.ndarray:
    """:func:`anchor_by_bones` by casting every bone's ray for every particle: the reference
    the pruned search is tested against (same parameters and results)."""
    free = np.flatnonzero(~np.asarray(is_root, dtype=bool))
    best_score = np.full(len(points), np.inf)
    reach = _reach(distance)
    for j, bone in enumerate(rays.bones):
        origin, ray, length, cosine = _rays_of_bone(rays, j, points[free])
        usable = length > MIN_RAY_LENGTH
        index = free[usable]
        score, hits, eta = _scores(rays, j, query, points[index], origin[usable], ray[usable], length[usable],
                                   cosine[usable], reach[index], sigma)
        better = score < best_score[index]
        best_score[index[better]] = score[better]
        _take(best, index[better], int(bone), hits, eta, better)
    return np.isfinite(best_score)
