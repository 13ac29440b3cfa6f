"""The spacing term, beyond the paper: segments keep their share of their strand's length.

Eq. 7 measures directions only, so a segment may shrink or stretch freely and particles slide
along their strand: on short hair moved to a larger head, a twentieth of the segments ended
below 0.01 of their strand's overall stretch and another twentieth above 3 (``bench/fidelity.py``),
which no simulator takes as rest lengths. The spacing term adds, per segment ``s`` of strand ``k``,

    ``lambda_s excess(l_s / t_s)^2``, with the rest length ``t_s = l-bar_s rho_k``

where ``l-bar_s`` is the source length, ``rho_k`` the initial transfer's whole-strand stretch
(its length over the source's) and ``excess`` how far the ratio lies outside a free band
``[low, high]`` (:func:`band_excess`; ``low = high = 1`` is the plain ``(l - t) / t``). A strand
may grow or shrink as a whole, as the body's proportions ask through Eq. 2-6, and its particles
may slide within the band, but no further. The term is dimensionless like Eq. 7, couples only a
segment's two particles (the fine level's strand-banded structure is kept), and
``lambda_s = 0`` is the paper's Eq. 1 exactly.

Outside the band its Hessian in the segment vector ``e`` (``l = |e|``, ``u = e / l``) is
``2 lambda_s (u u^T / t^2 + excess / (t l) (I - u u^T))``; the second part is negative below
the band and is then dropped (Gauss-Newton), which keeps it positive semi-definite. Within the
band the term and its derivatives are 0.

What it costs: Eq. 1's low segment angles on such pairs come from that sliding (a strand keeps
its source directions and folds its excess into collapsed segments), so even spacing gives
some angle back (docs/fidelity.md).
"""

from __future__ import annotations

import numpy as np

from hairport.solver.jit import kernel
from hairport.solver.mesh.polyline import strand_stretch

#: the weight ``lambda_s`` that keeps segments evenly spaced, chosen by ``bench/fidelity.py`` over
#: every ordered MakeHuman pair and groom style (docs/fidelity.md): with the shape carry it keeps
#: the in-strand length ratios' p5-p95 within [0.8, 1.25] on all 150 and the strands' bends twice
#: as close to the source's as Eq. 1 alone (whose low segment angles come from collapsed segments)
EVEN_SPACING_WEIGHT = 10.0
#: the default: off (Eq. 1), because even spacing gives back segment angle where Eq. 1 folds a
#: strand into collapsed segments (short hair: up to 0.03 rad more; the fringe of the quality
#: pair then loses to the pushed-out root translation by 0.002 rad)
SPACING_WEIGHT = 0.0
#: the band of ``l / t`` the term leaves free: segments may slide this much along their strand
#: for Eq. 7 at no cost, inside the issue's [0.8, 1.25] for the 5th-95th percentiles with a
#: margin (``bench/fidelity.py``: curly hair to the heavy male 0.069 rad instead of 0.088 with
#: the plain quadratic at weight 1, 0.13 instead of 0.134 rad on long and fringe)
SPACING_BAND = (0.85, 1.18)


def segment_rest_lengths(segments: np.ndarray, source_lengths: np.ndarray, initial: np.ndarray) -> np.ndarray:
    """:func:`.polyline.rest_lengths` per segment of a segment list (strands are runs of consecutive segments
    ``(a, a + 1)``; a run breaks where a segment does not start at its predecessor's end).

    Parameters
    ----------
    segments : (M, 2) int64
    source_lengths : (M,) float64
    initial : (N, 3) float64

    Returns
    -------
    rest : (M,) float64
    """
    m = len(segments)
    new_strand = np.ones(m, dtype=bool)
    new_strand[1:] = segments[1:, 0] != segments[:-1, 1]
    segment_strand = np.cumsum(new_strand) - 1
    n_strands = int(segment_strand[-1]) + 1 if m else 0
    lengths = np.linalg.norm(initial[segments[:, 1]] - initial[segments[:, 0]], axis=1)
    return source_lengths * strand_stretch(source_lengths, lengths, segment_strand, n_strands)[segment_strand]


@kernel
def band_excess(ratio, low, high):
    """How far ``ratio = l / t`` lies outside the free band ``[low, high]`` (negative below, 0 within).

    ``low = high = 1`` gives ``l / t - 1``, the plain quadratic term."""
    return min(ratio - low, 0.0) + max(ratio - high, 0.0)


def band_excesses(ratio: np.ndarray, low: float, high: float) -> np.ndarray:
    """:func:`band_excess` of ``(M,)`` ratios, in numpy (the reference)."""
    return np.minimum(ratio - low, 0.0) + np.maximum(ratio - high, 0.0)


def spacing_residuals(length: np.ndarray, rest: np.ndarray, band: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """The term's residual per segment: ``l / t`` outside the free ``band`` (0 where ``t`` is 0: no term).

    Parameters
    ----------
    length, rest : (M,) float64
    band : (low, high)
    """
    ratio = np.divide(length, rest, out=np.ones(len(length)), where=rest > 0)
    return np.where(rest > 0, band_excesses(ratio, *band), 0.0)


def spacing_gradients(unit: np.ndarray, length: np.ndarray, rest: np.ndarray, weight: float,
                      band: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """The term's gradient in each segment vector ``e``: ``2 lambda excess / t u``.

    Parameters
    ----------
    unit : (M, 3) float64
    length, rest : (M,) float64
    weight : float
    band : (low, high)

    Returns
    -------
    gradient : (M, 3) float64
    """
    scale = np.divide(spacing_residuals(length, rest, band), rest, out=np.zeros(len(rest)), where=rest > 0)
    return (2.0 * weight * scale)[:, None] * unit


def spacing_blocks(unit: np.ndarray, length: np.ndarray, rest: np.ndarray, weight: float,
                   band: tuple[float, float] = (1.0, 1.0)) -> np.ndarray:
    """The term's Hessian in each segment vector, PSD (see the module's note; 0 within the free band).

    Returns
    -------
    blocks : (M, 3, 3) float64
    """
    excess = spacing_residuals(length, rest, band)
    outside = (excess != 0.0) & (rest > 0)
    inverse_square = np.divide(1.0, rest * rest, out=np.zeros(len(rest)), where=outside)
    tangential = np.divide(np.maximum(excess, 0.0), rest * length, out=np.zeros(len(rest)), where=outside)
    outer = unit[:, :, None] * unit[:, None, :]
    return 2.0 * weight * ((inverse_square - tangential)[:, None, None] * outer
                           + tangential[:, None, None] * np.eye(3)[None])
