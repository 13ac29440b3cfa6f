"""Optimal-step non-rigid ICP (Amberg, Romdhani & Vetter 2007) of a source patch onto a target surface.

For each stiffness ``alpha`` of the schedule, stiff to soft, the loop alternates (i) the
closest target points of the deformed source with the rejections of
:meth:`~.surface.TargetSurface.match` (too far, normals disagreeing, on the target's border)
and (ii) the exact minimiser of the quadratic cost of :mod:`.system` for those
correspondences, until no vertex moves farther than the tolerance.

Choices, measured with ``bench/wrap.py`` (average-female onto the other presets' heads
remeshed to 20k vertices, a hair region of ~5k vertices):

* Every vertex's data term weighs alike (Amberg's 0/1 weights). Weighing it by the vertex's
  share of the patch's area (the scalp is meshed more coarsely than the face) brought the
  scalp 0.27 mm nearer the truth on average over the five presets but the head and neck
  0.35 mm farther (the face's features then pull less), and the residual up by 0.04 mm.
* The matrix changes with ``alpha``, the landmark weight and the accepted correspondences.
  Refactoring whenever the accepted set changed took 25 factorisations per wrap (it changes a
  little at every update); refactoring once per stiffness step, holding a vertex rejected
  since in place and letting one accepted since wait for the next step, takes 7-9 and ends
  within 0.05 mm of it, 2x faster (:data:`REFACTOR_SHARE`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hairport.solver.wrap.factor import SymmetricFactor
from hairport.solver.wrap.landmarks import Landmarks
from hairport.solver.wrap.options import WrapOptions
from hairport.solver.wrap.surface import TargetSurface, vertex_normals
from hairport.solver.wrap.system import AmbergSystem

#: the factor of a stiffness step is redone when the accepted correspondences differ from those
#: it was made with in more than this share of the vertices; below it, newly rejected vertices
#: are held in place and newly accepted ones wait for the next step (module docstring)
REFACTOR_SHARE = 0.05


@dataclass(frozen=True)
class Normalisation:
    """Normalised coordinates ``(p - centre) / scale`` of the fitting system.

    Attributes
    ----------
    centre : (3,) float64
        Meters.
    scale : float
        Meters per unit.
    """

    centre: np.ndarray
    scale: float

    @classmethod
    def of(cls, points: np.ndarray) -> "Normalisation":
        """Centroid and RMS radius of ``points (n, 3)``."""
        centre = points.mean(axis=0)
        radius = float(np.sqrt(np.mean(np.sum((points - centre) ** 2, axis=1))))
        return cls(centre, radius if radius > 0 else 1.0)

    def forward(self, points: np.ndarray) -> np.ndarray:
        return (points - self.centre) / self.scale

    def back(self, points: np.ndarray) -> np.ndarray:
        return points * self.scale + self.centre


@dataclass
class FitLog:
    """What the loop did: correspondence updates, factorisations, accepted share per step."""

    iterations: int = 0
    factorisations: int = 0
    accepted_share: list[float] = field(default_factory=list)


def fit(points: np.ndarray, triangles: np.ndarray, edges: np.ndarray, surface: TargetSurface,
        landmarks: Landmarks, options: WrapOptions) -> tuple[np.ndarray, FitLog]:
    """Deform a source patch onto the target surface.

    Parameters
    ----------
    points : (n, 3) float64
        The patch's vertices after the start (m).
    triangles : (t, 3) int64
        Its faces, local ids.
    edges : (m, 2) int64
        Its undirected edges, local ids.
    surface : TargetSurface
    landmarks : Landmarks
    options : WrapOptions

    Returns
    -------
    positions : (n, 3) float64
        The deformed patch (m).
    log : FitLog
    """
    frame = Normalisation.of(points)
    system = AmbergSystem(frame.forward(points), edges, options.gamma, landmarks.corners, landmarks.weights)
    factor = SymmetricFactor()
    landmark_targets = frame.forward(landmarks.targets)
    min_cosine = float(np.cos(np.radians(options.max_normal_angle_deg)))
    transforms, hint, log = system.identity(), None, FitLog()
    for step, alpha in enumerate(options.stiffness):
        # the landmarks together weigh ``landmark_weight`` times the data term of the whole patch
        beta = np.sqrt(options.landmark_weight(step) * system.n / len(landmarks.names)) if len(landmarks.names) else 0.0
        factored = None
        for _ in range(options.inner_iterations):
            current = frame.back(system.positions(transforms))
            match = surface.match(current, vertex_normals(current, triangles), options.max_distance_m, min_cosine, hint)
            hint = match.faces
            if factored is None or np.count_nonzero(factored != match.accepted) > REFACTOR_SHARE * system.n:
                factored = match.accepted
                factor.factor(system.matrix(alpha, factored.astype(np.float64), beta))
            # a vertex weighted in the factor but rejected now is held where it is (no pull)
            targets = np.where(match.accepted[:, None], match.closest, current)
            rhs = system.rhs(factored.astype(np.float64), frame.forward(targets), transforms, beta, landmark_targets)
            updated = factor.solve(rhs)
            moved = np.abs(system.positions(updated) - system.positions(transforms)).max() * frame.scale
            transforms = updated
            log.iterations += 1
            if moved < options.tolerance_m:
                break
        log.accepted_share.append(float(np.mean(match.accepted)))
    log.factorisations = factor.factorisations
    return frame.back(system.positions(transforms)), log
