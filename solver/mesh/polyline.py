"""Polylines and segments: arc length, closest points on segments, strands' stretch and rest lengths."""

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


def strand_stretch(source_lengths: np.ndarray, lengths: np.ndarray, segment_strand: np.ndarray,
                   n_strands: int) -> np.ndarray:
    """Each strand's length over its source length, 0 where the source strand has no length.

    Parameters
    ----------
    source_lengths, lengths : (M,) float64
        Segment lengths in the source and now.
    segment_strand : (M,) int64
        The strand of each segment.
    n_strands : int

    Returns
    -------
    stretch : (S,) float64
    """
    source_total = np.bincount(segment_strand, weights=source_lengths, minlength=n_strands)
    total = np.bincount(segment_strand, weights=lengths, minlength=n_strands)
    return np.divide(total, source_total, out=np.zeros(n_strands), where=source_total > 0)


def rest_lengths(source_points: np.ndarray, initial: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """The rest length ``t`` of the segment starting at each particle (0 at tips): its source length
    times its strand's stretch from ``source_points`` to ``initial`` (the spacing term's and the shape
    carry's, :mod:`hairport.solver.adaptation.problem.spacing`, :mod:`hairport.solver.transfer.carry`).

    A strand's sums run over its own rows only, in order, so the rows of a run of strands
    equal the same rows computed over the whole hairstyle bit for bit (fine-level chunks).

    Parameters
    ----------
    source_points, initial : (N, 3) float64
        The source particles and the initial transfer ``p-hat``.
    offsets : (S+1,) int64
        CSR strands of these rows.

    Returns
    -------
    rest : (N,) float64
    """
    n = len(source_points)
    starts = np.ones(n, dtype=bool)
    starts[np.asarray(offsets[1:], dtype=np.int64) - 1] = False
    segment_start = np.flatnonzero(starts)
    source_lengths = np.linalg.norm(source_points[segment_start + 1] - source_points[segment_start], axis=1)
    lengths = np.linalg.norm(initial[segment_start + 1] - initial[segment_start], axis=1)
    n_strands = len(offsets) - 1
    segment_strand = np.repeat(np.arange(n_strands), np.maximum(np.diff(offsets) - 1, 0))
    stretch = strand_stretch(source_lengths, lengths, segment_strand, n_strands)
    rest = np.zeros(n)
    rest[segment_start] = source_lengths * stretch[segment_strand]
    return rest
