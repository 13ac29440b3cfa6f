"""Every number hairport reports (DESIGN.md section 4): the same in tests, bench, API and reports.

Convention: particles ``(N, 3) float64`` in meters; two hairstyles compared particle by
particle share one CSR layout.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hairport.solver.adaptation.problem.energies import EnergyTerms, EnergyWeights, shape_values, source_directions
from hairport.solver.adaptation.problem.spacing import spacing_residuals
from hairport.solver.adaptation.source.neighbours import Neighbours, neighbour_average
from hairport.solver.jit import parallel_kernel, prange, warms
from hairport.solver.mesh.polyline import rest_lengths
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.mesh.segment_crossing import SegmentCrossings, crossing_segments
from hairport.solver.model.hair import DEGENERATE_SEGMENT_M, Hair

#: a particle counts as closer than eps_c only when it is short by more than this (m): the
#: solver meets the clearance to its QP tolerance, and 1 um is far below anything visible
CLEARANCE_REPORT_TOLERANCE = 1e-6
#: particles per block of the segment figures (bounds their temporaries to a few tens of MB)
METRICS_CHUNK = 1 << 18


def mean_particle_distance(points: np.ndarray, reference: np.ndarray) -> float:
    """Mean Euclidean distance (m) between corresponding particles ``(N, 3)``."""
    return float(np.mean(np.linalg.norm(points - reference, axis=1))) if len(points) else 0.0


def hair_body_relation_change(points: np.ndarray, source_points: np.ndarray, is_root: np.ndarray,
                              body: MeshQuery, source_body: MeshQuery) -> float:
    """Mean change (m) of each non-root particle's offset to its closest body point, result against source.

    A particle at offset ``s - c_S(s)`` from the source body should sit at about the same offset ``p - c_T(p)``
    from the target: ``|(p - c_T(p)) - (s - c_S(s))|``, averaged (0 when the hair keeps its relation to the
    body exactly; a strand lying on the skin that ends up a few millimetres off it counts those millimetres).

    Parameters
    ----------
    points, source_points : (N, 3) float64
        The result and the source hairstyle.
    is_root : (N,) bool
    body, source_body : MeshQuery
        The target and the source bodies.
    """
    free = np.flatnonzero(~np.asarray(is_root, dtype=bool))
    if len(free) == 0:
        return 0.0
    total = 0.0
    for start in range(0, len(free), METRICS_CHUNK):  # bounds the queries' temporaries
        rows = free[start : start + METRICS_CHUNK]
        offset = points[rows] - body.signed_distance(points[rows]).closest
        source_offset = source_points[rows] - source_body.signed_distance(source_points[rows]).closest
        total += float(np.linalg.norm(offset - source_offset, axis=1).sum())
    return total / len(free)


def vector_angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle (rad) between rows of ``(M, 3)`` vectors, ``atan2(|a x b|, a . b)``: accurate for tiny angles.

    Returns
    -------
    angles : (M,) float64
    """
    return np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.einsum("ij,ij->i", a, b))


def segment_angles(points: np.ndarray, reference: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Angle (rad) between corresponding segments ``(M, 2)`` of two hairstyles (:func:`vector_angles`).

    Returns
    -------
    angles : (M,) float64
    """
    return vector_angles(points[segments[:, 1]] - points[segments[:, 0]],
                         reference[segments[:, 1]] - reference[segments[:, 0]])


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
    free = np.flatnonzero(~np.asarray(is_root, dtype=bool))
    distance = np.empty(len(free))
    for start in range(0, len(free), METRICS_CHUNK):  # bounds the query's temporaries
        rows = free[start : start + METRICS_CHUNK]
        distance[start : start + len(rows)] = query.signed_distance(points[rows]).distance
    return penetration_stats(distance, eps_c)


def penetration_stats(distance: np.ndarray, eps_c: float) -> dict:
    """:func:`penetration`'s statistics of the signed distances ``(N_free,)`` of the non-root particles."""
    return {
        "inside": int(np.sum(distance < 0.0)),
        "below_clearance": int(np.sum(distance < eps_c - CLEARANCE_REPORT_TOLERANCE)),
        "min_distance": float(distance.min()) if len(distance) else float("inf"),
        "distance": distance,
    }


def particle_distances(stats: dict, at_root: np.ndarray) -> np.ndarray:
    """(N,) float64: the signed distances of :func:`penetration`'s ``stats`` (one per particle not at a root) in
    their particles' places, 0 at the roots."""
    at_root = np.asarray(at_root, dtype=bool)
    distance = np.zeros(len(at_root))
    distance[~at_root] = stats["distance"]
    return distance


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


def interstrand_residual(neighbours: Neighbours, points: np.ndarray, source_points: np.ndarray) -> np.ndarray:
    """Eq. 10's residual ``(K p)_i - L-bar_i`` of every particle, without the operator ``K``.

    ``K`` is linear, so the residual is ``K (p - p-bar)``, i.e. per particle
    ``sum_j w_ij (d_i - d_j)`` with ``d = p - p-bar`` (:func:`.neighbours.neighbour_average`).

    Parameters
    ----------
    neighbours : Neighbours
        Eq. 8-9 over all strands, one row per particle.
    points, source_points : (N, 3) float64

    Returns
    -------
    residual : (N, 3) float64
    """
    displacement = points - source_points
    residual = neighbour_average(neighbours, displacement)
    np.subtract(neighbours.weight.sum(axis=1)[:, None] * displacement, residual, out=residual)
    return residual


def interstrand_residual_norms(neighbours: Neighbours, points: np.ndarray, source_points: np.ndarray) -> np.ndarray:
    """``|| (K p)_i - L-bar_i ||`` per particle (m) without ``(N, 3)`` temporaries (compiled;
    the norms of :func:`interstrand_residual`, the reference).

    Returns
    -------
    norms : (N,) float64
    """
    norms = np.empty(len(points))
    _residual_norms(np.ascontiguousarray(neighbours.index), np.ascontiguousarray(neighbours.weight),
                    np.ascontiguousarray(points, dtype=np.float64), np.ascontiguousarray(source_points, dtype=np.float64),
                    norms)
    return norms


@parallel_kernel
def _residual_norms(index, weight, points, source_points, norms):
    for i in prange(index.shape[0]):
        total = 0.0
        x = y = z = 0.0
        for j in range(index.shape[1]):
            w, p = weight[i, j], index[i, j]
            total += w
            x += w * (points[p, 0] - source_points[p, 0])
            y += w * (points[p, 1] - source_points[p, 1])
            z += w * (points[p, 2] - source_points[p, 2])
        x = total * (points[i, 0] - source_points[i, 0]) - x
        y = total * (points[i, 1] - source_points[i, 1]) - y
        z = total * (points[i, 2] - source_points[i, 2]) - z
        norms[i] = np.sqrt(x * x + y * y + z * z)


@warms
def _warm() -> None:
    for dtype in (np.int32, np.int64):
        _residual_norms(np.zeros((1, 2), dtype), np.ones((1, 2)), np.ones((1, 3)), np.zeros((1, 3)), np.empty(1))


def interstrand_error(neighbours: Neighbours, points: np.ndarray, source_points: np.ndarray) -> float:
    """Mean ``|| L_i(p) - L-bar_i ||`` over particles (m): how much neighbourhoods changed."""
    return float(np.mean(interstrand_residual_norms(neighbours, points, source_points))) if len(points) else 0.0


@dataclass(frozen=True)
class SegmentFigures:
    """Eq. 7 and the segment angles of a result against its source, over all segments."""

    count: int
    angle_sum: float
    angle_max: float
    strand_shape: float


def segment_figures(points: np.ndarray, source_points: np.ndarray, offsets: np.ndarray,
                    chunk: int = METRICS_CHUNK) -> SegmentFigures:
    """Segment angles (as :func:`segment_angles`) and Eq. 7's value (as
    :func:`~.adaptation.problem.energies.energy_terms`) of every segment, a block of particles at a time.

    A degenerate source segment (:data:`~hairport.solver.model.hair.DEGENERATE_SEGMENT_M`) has no
    direction, so no angle to measure: it counts in Eq. 7's value (its weld) but not in the angles.

    Parameters
    ----------
    points, source_points : (N, 3) float64
    offsets : (S+1,) int64
    chunk : int
        Particles per block (bounds the temporaries).
    """
    n = len(points)
    is_tip = np.zeros(n, dtype=bool)
    is_tip[np.asarray(offsets)[1:] - 1] = True
    count, angle_sum, angle_max, shape = 0, 0.0, 0.0, 0.0
    step = max(1, int(chunk))
    for start in range(0, n - 1, step):
        stop = min(n - 1, start + step)  # segments (i, i + 1) for i in [start, stop)
        starts = ~is_tip[start:stop]
        a = np.diff(points[start : stop + 1], axis=0)[starts]
        b = np.diff(source_points[start : stop + 1], axis=0)[starts]
        directions = source_directions(b)
        shaped = directions.any(axis=1)
        angles = vector_angles(a[shaped], b[shaped])
        count += len(angles)
        angle_sum += float(angles.sum())
        angle_max = max(angle_max, float(angles.max(initial=0.0)))
        shape += float(np.sum(shape_values(a, directions)))
    return SegmentFigures(count, angle_sum, angle_max, shape)


def bend_errors(points: np.ndarray, source_points: np.ndarray, offsets: np.ndarray,
                chunk: int = METRICS_CHUNK) -> tuple[float, float]:
    """How each strand's bends changed, a block of ``chunk`` joints at a time: mean and max over interior
    particles ``(N, 3)`` (CSR ``offsets``) of ``|turn - source turn|`` (rad), the turn being the angle
    between a particle's two segments. Unlike the segment angles it does not see a strand turned as a
    whole, and it does see a kink that a collapsed segment hides from them (a segment of almost no
    length may point anywhere). A joint next to a degenerate source segment
    (:data:`~hairport.solver.model.hair.DEGENERATE_SEGMENT_M`) has no source turn and is left out."""
    offsets = np.asarray(offsets, dtype=np.int64)
    interior = np.ones(len(points), dtype=bool)
    interior[offsets[:-1]] = False
    interior[np.maximum(offsets[1:] - 1, 0)] = False
    if len(points) > 2:
        step = np.diff(source_points, axis=0)
        short = np.einsum("ij,ij->i", step, step) <= DEGENERATE_SEGMENT_M**2  # segment (i, i + 1)
        interior[1:-1] &= ~short[:-1] & ~short[1:]
    joints = np.flatnonzero(interior)
    total, largest = 0.0, 0.0

    def turns(p: np.ndarray, j: np.ndarray) -> np.ndarray:
        return vector_angles(p[j] - p[j - 1], p[j + 1] - p[j])

    for start in range(0, len(joints), max(1, int(chunk))):
        j = joints[start : start + max(1, int(chunk))]
        error = np.abs(turns(points, j) - turns(source_points, j))
        total += float(error.sum())
        largest = max(largest, float(error.max(initial=0.0)))
    return (total / len(joints) if len(joints) else 0.0), largest


def spacing_energy(points: np.ndarray, source: Hair, initial: np.ndarray, band: tuple[float, float]) -> float:
    """The spacing term's value (unweighted) at ``points (N, 3)``, its rest lengths from ``initial``
    (:mod:`.adaptation.problem.spacing`)."""
    rest = rest_lengths(source.points, initial, source.offsets)
    starts = np.flatnonzero((rest > 0) & ~source.short_segments)  # a weld has no spacing term
    length = np.linalg.norm(points[starts + 1] - points[starts], axis=1)
    return float(np.sum(spacing_residuals(length, rest[starts], band) ** 2))


#: the percentiles the length ratios are reported at
LENGTH_PERCENTILES = (5, 50, 95)


def length_ratios(points: np.ndarray, source_points: np.ndarray, offsets: np.ndarray,
                  chunk: int = METRICS_CHUNK) -> dict[str, dict[str, float]]:
    """How segments and strands changed length: percentiles (:data:`LENGTH_PERCENTILES`) of each segment's
    length over its source length (``segment_length_ratio``), of that over its strand's whole-length ratio
    (``segment_length_ratio_in_strand``: 1 everywhere when a strand grew or shrank evenly) and of each strand's
    length over its source's (``strand_length_ratio``). Degenerate segments and collapsed strands (no longer
    than :data:`~hairport.solver.model.hair.DEGENERATE_SEGMENT_M`) are left out.

    Parameters
    ----------
    points, source_points : (N, 3) float64
    offsets : (S+1,) int64
    chunk : int
        Particles per block (bounds the float64 temporaries; the ratios are kept as float32).
    """
    offsets = np.asarray(offsets, dtype=np.int64)
    n, strands = len(points), len(offsets) - 1
    segment_strand = np.repeat(np.arange(strands), np.maximum(np.diff(offsets) - 1, 0))
    segment_start = np.flatnonzero(np.isin(np.arange(max(n - 1, 0)), offsets[1:] - 1, invert=True))
    ratio = np.empty(len(segment_start), dtype=np.float32)
    length, source_length = np.zeros(strands), np.zeros(strands)
    for first in range(0, len(segment_start), max(1, int(chunk))):
        rows = slice(first, first + max(1, int(chunk)))
        starts = segment_start[rows]
        now = np.linalg.norm(points[starts + 1] - points[starts], axis=1)
        before = np.linalg.norm(source_points[starts + 1] - source_points[starts], axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):  # a degenerate segment has no ratio
            ratio[rows] = np.where(before > DEGENERATE_SEGMENT_M, now / before, np.nan)
        length += np.bincount(segment_strand[rows], weights=now, minlength=strands)
        source_length += np.bincount(segment_strand[rows], weights=before, minlength=strands)
    with np.errstate(divide="ignore", invalid="ignore"):  # nor has a collapsed strand
        strand_ratio = np.where(source_length > DEGENERATE_SEGMENT_M, length / source_length, np.nan)
        in_strand = ratio / strand_ratio[segment_strand].astype(np.float32)

    def percentiles(values: np.ndarray) -> dict[str, float]:
        values = values[np.isfinite(values)]
        if len(values) == 0:
            return {f"p{p}": float("nan") for p in LENGTH_PERCENTILES}
        return {f"p{p}": float(v) for p, v in zip(LENGTH_PERCENTILES, np.percentile(values, LENGTH_PERCENTILES))}

    return {"segment_length_ratio": percentiles(ratio), "segment_length_ratio_in_strand": percentiles(in_strand),
            "strand_length_ratio": percentiles(strand_ratio)}


def hairstyle_metrics(
    points: np.ndarray,
    source: Hair,
    initial: np.ndarray,
    root_targets: np.ndarray,
    neighbours: Neighbours,
    query: MeshQuery,
    eps_c: float,
    weights: EnergyWeights = EnergyWeights(),
    body: MeshQuery | None = None,
    penetration_stats: dict | None = None,
    crossings: SegmentCrossings | None = None,
) -> dict:
    """All section-4 metrics of a retargeted hairstyle, as a JSON-ready dict.

    Parameters
    ----------
    points : (N, 3) float64
        The result.
    source : Hair
        The source hairstyle (segment angles and Eq. 7/10 are measured against it).
    initial : (N, 3) float64
        The initial transfer ``p-hat`` (hair-body reference).
    root_targets : (S, 3) float64
    neighbours : Neighbours
        Eq. 8-9 over all strands of the source, one row per particle (Eq. 10's term).
    query : MeshQuery
        The target body (the roots' distance to its surface).
    eps_c : float
    weights : EnergyWeights
    body : MeshQuery, optional
        The target's collision surface (:func:`.mesh.collision.collision_query`) for the
        penetration figures; ``query`` by default.
    penetration_stats : dict, optional
        :func:`penetration` of ``points`` against that body, when the caller measured it already.
    crossings : SegmentCrossings, optional
        :func:`~.mesh.segment_crossing.crossing_segments` of ``points`` against that body, likewise.
    """
    n = len(points)
    is_root = source.is_root
    body = query if body is None else body
    pen = penetration_stats or penetration(points, source.at_root, body, eps_c)
    segment_rows = source.segments
    if crossings is None:
        crossings = crossing_segments(points, segment_rows, source.at_root, body,
                                      particle_distances(pen, source.at_root))
    segments = segment_figures(points, source.points, source.offsets)
    residual_norm = interstrand_residual_norms(neighbours, points, source.points)
    hair_body = sum(float(np.sum((points[rows] - initial[rows]) ** 2))
                    for rows in (slice(start, start + METRICS_CHUNK) for start in range(0, n, METRICS_CHUNK)))
    spacing = spacing_energy(points, source, initial, weights.spacing_band) if weights.spacing else 0.0
    terms = EnergyTerms(segments.strand_shape, float(np.sum(residual_norm**2)), hair_body, spacing)
    metrics = {
        "particles": n,
        "mean_segment_angle_rad": segments.angle_sum / segments.count if segments.count else 0.0,
        "max_segment_angle_rad": segments.angle_max,
        "mean_distance_to_initial_m": mean_particle_distance(points, initial),
        "interstrand_error_m": float(np.mean(residual_norm)) if n else 0.0,
        "penetrating_particles": pen["inside"],
        "particles_below_clearance": pen["below_clearance"],
        "min_signed_distance_m": pen["min_distance"],
        "crossing_segments": crossings.report(segment_rows, source.offsets),
        "energy_strand_shape_per_particle": terms.strand_shape / n,
        "energy_inter_strand_per_particle": terms.inter_strand / n,
        "energy_hair_body_per_particle": terms.hair_body / n,
        "energy_total_per_particle": terms.total(weights) / n,
    }
    if weights.spacing:
        metrics["energy_spacing_per_particle"] = terms.spacing / n
    metrics["mean_bend_error_rad"], metrics["max_bend_error_rad"] = bend_errors(points, source.points, source.offsets)
    metrics.update(length_ratios(points, source.points, source.offsets))
    metrics.update(root_errors(points[is_root], root_targets, query))
    return metrics
