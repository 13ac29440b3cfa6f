"""A drawn front hairline (Sec. 6.1): the curve document, its checks on the head, and arc length
measured on a smoothed copy.

Convention: points ``(N, 3) float64`` in meters. A hairline curve is a polyline over the front
of the head, from one ear to the other, with optional *turning points* (indices of its
corners) matched to the corners of the current hairline (:mod:`.scalp`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

from hairport.solver.mesh.polyline import polyline_arc_length
from hairport.solver.model.errors import InputError
from hairport.solver.model.json_input import parse_json
from hairport.solver.model.units import unit_scale

#: a drawn hairline needs at least this many points
MIN_CURVE_POINTS = 3
#: largest hairline file read (bytes): a curve is a few hundred points
MAX_CURVE_FILE_BYTES = 10 * 1024 * 1024
#: a curve point farther than this from the head surface is "off the head" (m)
MAX_DISTANCE_TO_HEAD = 0.02
#: the scalp's hairline follows mesh edges in a staircase a few mm deep; arc lengths along
#: hairlines and curves are measured on copies smoothed by a Gaussian of this width (m of
#: arc length), so that a smooth drawn curve is met at even spacing
ARC_SMOOTHING_M = 0.006
#: resampling step of the smoothing, as a fraction of ARC_SMOOTHING_M
SMOOTHING_STEP_SHARE = 0.25


@dataclass(frozen=True)
class HairlineCurve:
    """A drawn front hairline.

    Attributes
    ----------
    points : (P, 3) float64
        Meters, ordered from one end to the other.
    turning_points : (T,) int64
        Ascending indices into ``points`` of its corners (may be empty).
    """

    points: np.ndarray
    turning_points: np.ndarray


def parse_hairline_curve(document: object, source: str = "hairline curve") -> HairlineCurve:
    """Validate ``{"units": "m", "points": [[x, y, z], ...], "turning_points": [i, ...]}``.

    Raises
    ------
    InputError
        Not an object, unknown units, fewer than :data:`MIN_CURVE_POINTS` points, points that
        are not finite 3-vectors, repeated consecutive points, turning points out of range or
        not strictly increasing.
    """
    if not isinstance(document, dict):
        raise InputError("a hairline curve must be a JSON object with 'points'", source, "bad_curve")
    units = document.get("units", "m")
    try:
        scale = unit_scale(units)
    except (InputError, TypeError):
        raise InputError(f"unknown units {units!r}; expected m, dm, cm or mm", source, "unknown_units") from None
    try:
        points = np.asarray(document.get("points"), dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError("'points' must be a list of [x, y, z] numbers", source, "bad_curve") from None
    if points.ndim != 2 or points.shape[1] != 3:
        raise InputError("'points' must be a list of [x, y, z] numbers", source, "bad_curve")
    if len(points) < MIN_CURVE_POINTS:
        raise InputError(f"a hairline curve needs at least {MIN_CURVE_POINTS} points, got {len(points)}", source,
                         "too_few_points")
    if not np.isfinite(points).all():
        raise InputError("the curve has a non-finite coordinate", source, "non_finite")
    points = points * scale
    if (np.linalg.norm(np.diff(points, axis=0), axis=1) == 0).any():
        raise InputError("the curve repeats a point", source, "bad_curve")
    turning = np.asarray(document.get("turning_points", []), dtype=np.float64).ravel()
    if len(turning) and (not np.all(turning == np.round(turning)) or turning.min() < 0 or turning.max() >= len(points)):
        raise InputError(f"turning points must be indices in 0..{len(points) - 1}", source, "bad_curve")
    turning = turning.astype(np.int64)
    if len(turning) > 1 and np.any(np.diff(turning) <= 0):
        raise InputError("turning points must be strictly increasing", source, "bad_curve")
    return HairlineCurve(points, turning)


def read_hairline_curve(path: str | os.PathLike) -> HairlineCurve:
    """A hairline curve from a JSON file (see :func:`parse_hairline_curve`)."""
    source = os.fspath(path)
    size = os.path.getsize(source)
    if size > MAX_CURVE_FILE_BYTES:
        raise InputError(f"file has {size} bytes, more than the limit of {MAX_CURVE_FILE_BYTES}", source, "too_large")
    with open(source, "rb") as handle:
        document = parse_json(handle.read(), source, "bad_json")
    return parse_hairline_curve(document, source)


def check_curve_on_head(curve: HairlineCurve, distance_to_head: np.ndarray, front_view: np.ndarray,
                        source: str = "hairline curve") -> None:
    """Refuse curves off the head or crossing themselves.

    Parameters
    ----------
    curve : HairlineCurve
    distance_to_head : (P,) float64
        Unsigned distance (m) of each curve point to the head surface.
    front_view : (P, 2) float64
        The points in a 2D map of the head (e.g. a head parameterization) where a hairline
        must not cross itself.
    """
    far = np.flatnonzero(np.abs(distance_to_head) > MAX_DISTANCE_TO_HEAD)
    if len(far):
        raise InputError(
            f"{len(far)} curve points are more than {100 * MAX_DISTANCE_TO_HEAD:g} cm off the head "
            f"(first: point {far[0]}, {100 * abs(distance_to_head[far[0]]):.1f} cm)", source, "off_head")
    crossing = first_self_crossing(front_view)
    if crossing is not None:
        raise InputError(f"the curve crosses itself (segments {crossing[0]} and {crossing[1]})", source,
                         "self_intersecting")


def smooth_polyline(points: np.ndarray, width: float = ARC_SMOOTHING_M) -> np.ndarray:
    """A Gaussian-smoothed copy of a polyline, row for row.

    The polyline is resampled at even arc-length steps, each coordinate is convolved with a
    Gaussian of standard deviation ``width`` (m of arc length) and read back at the original
    vertices' arc lengths. The ends stay where they are: the samples are extended past each
    end by their point reflection through it, which the symmetric kernel averages back to the
    end. Independent of how densely the polyline is sampled.

    Parameters
    ----------
    points : (k, 3) float64
    width : float
        > 0 (m).

    Returns
    -------
    smoothed : (k, 3) float64
    """
    points = np.asarray(points, dtype=np.float64)
    arc = polyline_arc_length(points)
    step = SMOOTHING_STEP_SHARE * width
    samples = np.linspace(0.0, arc[-1], max(int(np.ceil(arc[-1] / step)) + 1, 2))
    resampled = np.column_stack([np.interp(samples, arc, points[:, k]) for k in range(points.shape[1])])
    sigma = width / (samples[1] - samples[0])
    pad = min(int(np.ceil(4.0 * sigma)), len(samples) - 1)
    extended = np.concatenate([
        2.0 * resampled[0] - resampled[pad:0:-1], resampled, 2.0 * resampled[-1] - resampled[-2:-2 - pad:-1]
    ])
    smooth = gaussian_filter1d(extended, sigma, axis=0, mode="nearest", truncate=4.0)[pad:pad + len(samples)]
    smooth[[0, -1]] = resampled[[0, -1]]
    return np.column_stack([np.interp(arc, samples, smooth[:, k]) for k in range(points.shape[1])])


def smoothed_arc_length(points: np.ndarray, width: float = ARC_SMOOTHING_M) -> np.ndarray:
    """(k,) cumulative arc length (m) of a polyline ``(k, 3)`` measured on its smoothed copy
    (:func:`smooth_polyline`): non-decreasing, 0 at the first vertex."""
    return polyline_arc_length(smooth_polyline(points, width))


def first_self_crossing(polyline: np.ndarray) -> tuple[int, int] | None:
    """The first pair of non-adjacent segments of a 2D polyline ``(P, 2)`` that cross, or None.

    All pairs are tested at once (a drawn hairline has at most a few hundred points).
    """
    a, b = polyline[:-1], polyline[1:]
    m = len(a)
    if m < 3:
        return None
    i, j = np.triu_indices(m, k=2)
    p, r = a[i], b[i] - a[i]
    q, s = a[j], b[j] - a[j]
    cross = r[:, 0] * s[:, 1] - r[:, 1] * s[:, 0]
    qp = q - p
    parallel = np.abs(cross) < 1e-300
    safe = np.where(parallel, 1.0, cross)
    t = (qp[:, 0] * s[:, 1] - qp[:, 1] * s[:, 0]) / safe
    u = (qp[:, 0] * r[:, 1] - qp[:, 1] * r[:, 0]) / safe
    hit = ~parallel & (t >= 0) & (t <= 1) & (u >= 0) & (u <= 1)
    if not hit.any():
        return None
    first = int(np.argmax(hit))
    return int(i[first]), int(j[first])
