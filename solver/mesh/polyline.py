"""Polylines and segments: arc length, closest points on segments."""

from __future__ import annotations

import numpy as np

#: segments shorter than this (m) are treated as having this length (no direction to divide by)
MIN_SEGMENT_LENGTH = 1e-9


def polyline_arc_length(points: np.ndarray) -> np.ndarray:
    """Cumulative arc length of a polyline.

    Parameters
    ----------
    points : (k, d) float64

    Returns
    -------
    arc : (k,) float64
        0 at the first point, non-decreasing.
    """
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])


def closest_points_on_segments(points: np.ndarray, heads: np.ndarray, tails: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest point on each segment to each point, for every (point, segment) pair.

    Parameters
    ----------
    points : (N, 3) float64
    heads, tails : (B, 3) float64

    Returns
    -------
    t : (N, B) float64
        Segment parameter in [0, 1].
    closest : (N, B, 3) float64
    """
    axis = tails - heads
    length_sq = np.maximum(np.einsum("ij,ij->i", axis, axis), np.finfo(float).tiny)
    t = np.clip(((points[:, None, :] - heads[None]) * axis[None]).sum(-1) / length_sq[None], 0.0, 1.0)
    return t, heads[None] + t[..., None] * axis[None]
