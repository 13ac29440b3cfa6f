"""Every number hairport reports (DESIGN.md section 4): the same in tests, bench, API and reports.

Convention: particles ``(N, 3) float64`` in meters; two hairstyles compared particle by
particle share one CSR layout.
"""

from __future__ import annotations

import numpy as np

from hairport.solver.adaptation.energies import EnergyWeights, ShapeModel, energy_terms
from hairport.solver.mesh.query import MeshQuery

#: a particle counts as closer than eps_c only when it is short by more than this (m): the
#: solver meets the clearance to its QP tolerance, and 1 um is far below anything visible
CLEARANCE_REPORT_TOLERANCE = 1e-6


def mean_particle_distance(points: np.ndarray, reference: np.ndarray) -> float:
    """Mean Euclidean distance (m) between corresponding particles ``(N, 3)``."""
    return float(np.mean(np.linalg.norm(points - reference, axis=1))) if len(points) else 0.0


def segment_angles(points: np.ndarray, reference: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Angle (rad) between corresponding segments ``(M, 2)`` of two hairstyles.

    Uses ``atan2(|a x b|, a . b)``, accurate for tiny angles.

    Returns
    -------
    angles : (M,) float64
    """
    a = points[segments[:, 1]] - points[segments[:, 0]]
    b = reference[segments[:, 1]] - reference[segments[:, 0]]
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.einsum("ij,ij->i", a, b))


def mean_segment_angle(points: np.ndarray, reference: np.ndarray, segments: np.ndarray) -> float:
    """Mean of :func:`segment_angles` (rad)."""
    return float(np.mean(segment_angles(points, reference, segments))) if len(segments) else 0.0


def penetration(points: np.ndarray, is_root: np.ndarray, query: MeshQuery, eps_c: float) -> dict:
    """Signed-distance statistics of the non-root particles against a body.

    Parameters
    ----------
    query : MeshQuery
        The body, best its collision surface (:func:`.mesh.collision.collision_query`): then
        inside (a negative distance) is the body's inside at any depth, the test of the final
        check and of the solvers' constraints.

    Returns
    -------
    stats : dict
        ``inside`` (count inside the body), ``below_clearance`` (count below eps_c by
        more than :data:`CLEARANCE_REPORT_TOLERANCE`),
        ``min_distance`` (m), and ``distance`` ((N_free,) array, not for JSON).
    """
    free = ~is_root
    distance = query.signed_distance(points[free]).distance if free.any() else np.zeros(0)
    return {
        "inside": int(np.sum(distance < 0.0)),
        "below_clearance": int(np.sum(distance < eps_c - CLEARANCE_REPORT_TOLERANCE)),
        "min_distance": float(distance.min()) if len(distance) else float("inf"),
        "distance": distance,
    }


def root_errors(root_points: np.ndarray, root_targets: np.ndarray, query: MeshQuery) -> dict:
    """Distance of roots ``(S, 3)`` to their target positions and to the body surface (m)."""
    to_target = np.linalg.norm(root_points - root_targets, axis=1)
    to_surface = np.abs(query.signed_distance(root_points).distance)
    return {
        "root_to_target_max": float(to_target.max(initial=0.0)),
        "root_to_target_mean": float(to_target.mean()) if len(to_target) else 0.0,
        "root_to_surface_max": float(to_surface.max(initial=0.0)),
        "root_to_surface_mean": float(to_surface.mean()) if len(to_surface) else 0.0,
    }


def interstrand_error(model: ShapeModel, points: np.ndarray) -> float:
    """Mean ``|| L_i(p) - L-bar_i ||`` over particles (m): how much neighbourhoods changed."""
    return float(np.mean(np.linalg.norm(model.K @ points - model.source_features, axis=1)))


def hairstyle_metrics(
    points: np.ndarray,
    source_points: np.ndarray,
    initial: np.ndarray,
    is_root: np.ndarray,
    root_targets: np.ndarray,
    model: ShapeModel,
    query: MeshQuery,
    eps_c: float,
    weights: EnergyWeights = EnergyWeights(),
    body: MeshQuery | None = None,
) -> dict:
    """All section-4 metrics of a retargeted hairstyle, as a JSON-ready dict.

    Parameters
    ----------
    points : (N, 3) float64
        The result.
    source_points : (N, 3) float64
        The source hairstyle (segment angles are measured against it).
    initial : (N, 3) float64
        The initial transfer ``p-hat`` (hair-body reference).
    is_root : (N,) bool
    root_targets : (S, 3) float64
    model : ShapeModel
    query : MeshQuery
        The target body (the roots' distance to its surface).
    eps_c : float
    weights : EnergyWeights
    body : MeshQuery, optional
        The target's collision surface (:func:`.mesh.collision.collision_query`) for the
        penetration figures; ``query`` by default.
    """
    n = len(points)
    pen = penetration(points, is_root, query if body is None else body, eps_c)
    terms = energy_terms(model, points, initial)
    angles = segment_angles(points, source_points, model.segments)
    metrics = {
        "particles": n,
        "mean_segment_angle_rad": float(angles.mean()) if len(angles) else 0.0,
        "max_segment_angle_rad": float(angles.max(initial=0.0)),
        "mean_distance_to_initial_m": mean_particle_distance(points, initial),
        "interstrand_error_m": interstrand_error(model, points),
        "penetrating_particles": pen["inside"],
        "particles_below_clearance": pen["below_clearance"],
        "min_signed_distance_m": pen["min_distance"],
        "energy_strand_shape_per_particle": terms.strand_shape / n,
        "energy_inter_strand_per_particle": terms.inter_strand / n,
        "energy_hair_body_per_particle": terms.hair_body / n,
        "energy_total_per_particle": terms.total(weights) / n,
    }
    metrics.update(root_errors(points[is_root], root_targets, query))
    return metrics
