"""What a wrap gives back, how close it came to the target, and when it is refused.

The residual is the symmetric surface distance between the wrapped patch (the fitted
region's faces) and the target, restricted to where both have surface: wrapped vertices
whose closest target point is on the target's border (past a cut) do not count, nor points
of the target whose closest point on the wrapped patch is on the patch's border or farther
than :data:`FROM_TARGET_REACH_M` (target surface the region does not cover: a full body's
legs under a head region, which may also be closest to the underside of the chin). The
target's side is :data:`RESIDUAL_SAMPLES` points spread over its area (a fixed seed), not
its vertices, which a coarse box has eight of. ``coverage`` says how much of the patch
found target surface.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hairport.solver.model.errors import InputError
from hairport.solver.wrap.start import Similarity
from hairport.solver.wrap.surface import TargetSurface, vertex_normals

#: refusal limits of :func:`check_wrap`, measured (``bench/wrap.py --refusal``) on average-female
#: wrapped, with a hair region and with a head-and-neck region, onto the five other MakeHuman
#: presets remeshed to 5k and 20k vertices (whole bodies, heads cut at the neck, busts cut at
#: the chest: 60 good wraps) and onto spheres (r 10, 20 cm), a box (20 x 25 x 22 cm) and tori
#: (10/4, 30/10 cm). Good wraps: symmetric mean <= 0.36 mm, p95 <= 1.3 mm, normal agreement
#: >= 0.92 (whole-body regions on whole bodies, not in that run: p95 up to 2.8 mm). Bad ones:
#: agreement 0.52-0.79 (a head pressed onto a sphere folds its nose and ears), p95 3.9-84 mm
#: but 1.0 mm for the big torus, which takes the head on its tube (only the normals tell), mean
#: 0.6-17 mm. The limits sit between the two groups, with room on the good side (the same
#: groups with the default schedule and with two softer steps after it: agreement >= 0.92 / <= 0.79).
MAX_RESIDUAL_MEAN_M = 2e-3
MAX_RESIDUAL_P95_M = 5e-3
MIN_NORMAL_AGREEMENT = 0.85
#: a wrap whose fitted region finds target surface for fewer of its vertices than this share is
#: refused too (a whole body on a head cut at the neck covers 0.32, the region of a long groom 0.76)
MIN_COVERAGE = 0.2

#: points of the target's surface (area-uniform, fixed seed) whose distance to the patch is measured
RESIDUAL_SAMPLES = 20_000
#: target points farther than this (m) from the wrapped patch are surface the region does not
#: cover (the good wraps of bench/wrap.py have 95 % of their target points within 3 mm)
FROM_TARGET_REACH_M = 0.03


@dataclass(frozen=True)
class Residual:
    """Distances (m) of some points to a surface: ``mean``, 95th percentile ``p95``, ``max``; ``count`` points."""

    mean: float
    p95: float
    max: float
    count: int

    @classmethod
    def of(cls, distances: np.ndarray) -> "Residual":
        if len(distances) == 0:
            return cls(float("nan"), float("nan"), float("nan"), 0)
        return cls(float(np.mean(distances)), float(np.percentile(distances, 95)), float(np.max(distances)),
                   len(distances))

    def millimetres(self) -> str:
        """``mean a, p95 b, max c mm``."""
        return f"mean {self.mean * 1e3:.2f} mm, p95 {self.p95 * 1e3:.2f} mm, max {self.max * 1e3:.2f} mm"


@dataclass(frozen=True)
class SurfaceResidual:
    """Symmetric surface distance between the wrapped patch and the target (module docstring).

    Attributes
    ----------
    symmetric : Residual
        Over both directions' distances together.
    to_target : Residual
        Wrapped patch vertices to the target surface.
    from_target : Residual
        Target vertices to the wrapped patch.
    coverage : float
        Share of the patch's vertices whose closest target point is not on the target's border.
    agreement : float
        Share of those whose normal agrees with the target's there (within the wrap's angle).
    """

    symmetric: Residual
    to_target: Residual
    from_target: Residual
    coverage: float
    agreement: float


@dataclass(frozen=True)
class WrapResult:
    """A source body wrapped onto a target's shape.

    Attributes
    ----------
    vertices : (V, 3) float64
        The source's topology in the target's shape (m); outside the fitted region the
        vertices follow smoothly (:func:`~.region.follow`).
    region : (V,) bool
        The fitted source vertices.
    residual : SurfaceResidual
        Over the fitted region.
    landmark_errors : dict of str to float
        Distance (m) from each landmark's wrapped source point to its target point.
    iterations : int
        Correspondence updates of the non-rigid fit.
    factorisations : int
        Sparse factorisations it took.
    seconds : float
        Wall time of :func:`~hairport.solver.wrap.wrap_body`.
    start : Similarity
        The start's scale, rotation and translation of the source.
    """

    vertices: np.ndarray
    region: np.ndarray
    residual: SurfaceResidual
    landmark_errors: dict[str, float] = field(default_factory=dict)
    iterations: int = 0
    factorisations: int = 0
    seconds: float = 0.0
    start: Similarity | None = None


def surface_residual(patch_vertices: np.ndarray, triangles: np.ndarray, surface: TargetSurface,
                     min_cosine: float) -> SurfaceResidual:
    """The residual of a wrapped patch against the target (module docstring).

    Parameters
    ----------
    patch_vertices : (n, 3) float64
        The wrapped patch (m).
    triangles : (t, 3) int64
        Its faces, local ids.
    surface : TargetSurface
    min_cosine : float
        Normals agree when their cosine is at least this.
    """
    match = surface.match(patch_vertices, vertex_normals(patch_vertices, triangles), np.inf, min_cosine)
    to_target, past_cut = match.distance, match.border
    agree = np.einsum("ij,ij->i", match.normal, vertex_normals(patch_vertices, triangles)) >= min_cosine
    # the patch as a surface: its border tells the target parts the region does not cover
    samples = sample_surface(surface.vertices, surface.faces, RESIDUAL_SAMPLES)
    _, from_target, _, uncovered = TargetSurface(patch_vertices, triangles).closest(samples)
    forward, backward = to_target[~past_cut], from_target[~uncovered & (from_target <= FROM_TARGET_REACH_M)]
    covered = ~past_cut
    return SurfaceResidual(Residual.of(np.concatenate([forward, backward])), Residual.of(forward),
                           Residual.of(backward), float(np.mean(covered)) if len(covered) else 0.0,
                           float(np.mean(agree[covered])) if covered.any() else 0.0)


def sample_surface(vertices: np.ndarray, faces: np.ndarray, count: int, seed: int = 0) -> np.ndarray:
    """(count, 3) points spread uniformly over the area of a mesh (``vertices (V, 3)``, ``faces (F, 3)``),
    the same for the same seed."""
    rng = np.random.default_rng(seed)
    corners = vertices[faces]
    area = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    chosen = rng.choice(len(faces), size=count, p=area / area.sum())
    u, v = rng.random(count), rng.random(count)
    flip = u + v > 1.0
    u, v = np.where(flip, 1.0 - u, u), np.where(flip, 1.0 - v, v)
    a, b, c = corners[chosen, 0], corners[chosen, 1], corners[chosen, 2]
    return a + u[:, None] * (b - a) + v[:, None] * (c - a)


def check_wrap(result: WrapResult, name: str | None = None) -> None:
    """Refuse a wrap whose residual shows that the target's shape was not reached.

    Raises
    ------
    InputError
        ``wrap_failed``, with the residual, when the symmetric residual's mean passes
        :data:`MAX_RESIDUAL_MEAN_M`, its 95th percentile :data:`MAX_RESIDUAL_P95_M`, the normal
        agreement falls below :data:`MIN_NORMAL_AGREEMENT` or the coverage below :data:`MIN_COVERAGE`.
    """
    residual = result.residual
    symmetric = residual.symmetric
    reasons = []
    if not symmetric.mean <= MAX_RESIDUAL_MEAN_M:
        reasons.append(f"mean above {MAX_RESIDUAL_MEAN_M * 1e3:g} mm")
    if not symmetric.p95 <= MAX_RESIDUAL_P95_M:
        reasons.append(f"p95 above {MAX_RESIDUAL_P95_M * 1e3:g} mm")
    if not residual.agreement >= MIN_NORMAL_AGREEMENT:
        reasons.append(f"the normals of only {residual.agreement:.0%} of it agree with the target's "
                       f"(at least {MIN_NORMAL_AGREEMENT:.0%} needed)")
    if not residual.coverage >= MIN_COVERAGE:
        reasons.append(f"only {residual.coverage:.0%} of the fitted region found target surface "
                       f"(at least {MIN_COVERAGE:.0%} needed)")
    if reasons:
        raise InputError(
            f"the body could not be wrapped onto the target's shape: residual {symmetric.millimetres()} "
            f"over the fitted region ({'; '.join(reasons)}); is the target a body in hairport's axes "
            "(Y up, facing +Z)?", name, "wrap_failed")
