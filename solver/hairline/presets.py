"""Preset hairline edits: a new front hairline built from the current one (Section 7.5, Fig. 14-15).

Convention: the current front hairline is ``front (f, 3) float64`` (meters, on the head),
ordered from the character's right ear to its left ear, as :mod:`.scalp` extracts it. A
preset returns a :class:`.curve.HairlineCurve` with the same number of points, each the
old point moved along the head, and the old turning points, so that it goes through the
same correspondence as a drawn curve.

Points are described in spherical coordinates about the middle of the skull
(:attr:`~hairport.solver.body.head_frame.HeadFrame.centre`) in the head frame: azimuth ``theta`` around the up axis
(0 straight ahead) and elevation ``phi`` above the horizontal. A circle of constant
elevation on a round head looks straight from the front, and raising the elevation moves a
point back toward the crown (receding); lowering it moves it down the forehead or, near the
ears, down the temple. A preset sets each point's elevation and, for the shapes that
replace the current line (all but ``receding`` and ``sideburns``, which offset it), spreads
the azimuths evenly across the forehead band, so that parts of the hairline running down a
temple (constant azimuth) are not folded onto one point; the new point is where the ray
from the skull centre in that direction first meets the head.

The shapes are computed on a smoothed copy of the hairline (:func:`.curve.smooth_polyline`:
the hairline follows mesh edges in a staircase a few mm deep whose azimuth goes back and
forth, which a new elevation per point would fold): the full preset is a smooth curve, and
``amount`` blends each hairline point toward its point on it (then onto the head), so the
staircase fades out as the shape fades in. The ends never move.

The lateral position ``x`` in [-1, 1] is the smoothed arc length from the face's midline
(azimuth 0), normalised by the arc length from there to each end (the ears). Shapes act on
the forehead band ``|x| <= BAND`` and fade out toward the ears over ``BAND .. TAPER_END`` (a
cosine taper), so the ends, shared with the fixed back part of the hairline, never move;
``sideburns`` acts on the other side of the taper, in front of the ears. With ``phi0`` the
current elevation, ``phi_b`` its median over the middle of the forehead (``|x| <= CENTRE``),
``R`` the median distance of the hairline from the skull centre and ``A`` each preset's
amplitude in meters along the head (for a head of crown height
:data:`~hairport.solver.body.head_frame.REFERENCE_CROWN_M`, scaled with the head), the full shapes are::

    straight     phi_b                                 a line straight across the forehead
    round        phi_b - A/R (x/BAND)^2                an arch: the sides come down
    bell         phi_b - A/R (x/BAND)^4                a flat top, sides falling steeply
    triangular   phi_b + A/R (1/2 - |x|/BAND)          an upward point (the opposite of a peak)
    widows-peak  phi_b - A/R max(0, 1 - |x|/PEAK)      a V pointing down the forehead
    m-shape      phi_b + A/R exp(-((|x| - M)/W)^2)     receded temples around a central lock
    receding     phi0  + A/R (0.7 + 0.3 (x/BAND)^2)    the whole front moves back, the temples more
    sideburns    phi0  - A/R sin^2(pi (|x| - S0)/(S1 - S0)) on S0 <= |x| <= S1
                                                       tongues down in front of the ears

and the full edit's elevation is ``phi0 + taper(x) * (shape - phi0)``; ``amount = 0`` gives
the current hairline back exactly.
"""

from __future__ import annotations

import numpy as np

from hairport.solver.body.head_frame import REFERENCE_CROWN_M, HeadFrame
from hairport.solver.hairline.curve import HairlineCurve, smooth_polyline
from hairport.solver.mesh.polyline import polyline_arc_length
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.errors import InputError

PRESETS = ("straight", "round", "widows-peak", "m-shape", "bell", "triangular", "sideburns", "receding")
#: presets that offset the current hairline (keeping its azimuths) rather than replace it
OFFSET_PRESETS = ("sideburns", "receding")
#: amount used when a preset is named without one (``widows-peak`` == ``widows-peak:1``)
DEFAULT_AMOUNT = 1.0

#: half-width (in x) of the forehead band the shapes act on
BAND = 0.6
#: the shapes fade to nothing at this |x| (the ends, at the ears, are |x| = 1)
TAPER_END = 0.92
#: |x| below which the current elevation is the base level ``phi_b``
CENTRE = 0.25
#: amplitudes (m along the head, for a crown height of REFERENCE_CROWN_M)
ROUND_DROP_M = 0.02
BELL_DROP_M = 0.015
TRIANGULAR_RISE_M = 0.025
WIDOWS_PEAK_DEPTH_M = 0.02
M_SHAPE_RECESSION_M = 0.02
RECEDING_M = 0.02
SIDEBURNS_LENGTH_M = 0.025
#: half-width (in x) of the widow's peak
PEAK = 0.3
#: centre and width (in x) of the m-shape's temple recessions
M_CENTRE, M_WIDTH = 0.5, 0.18
#: the span of |x| where sideburns grow (the ears are at 1)
SIDEBURNS_SPAN = (0.62, 0.9)
#: elevations closer than this (rad) to the current one count as unmoved
UNMOVED_RAD = 1e-12


def unknown_preset(name: str) -> InputError:
    """The refusal of a preset name not in :data:`PRESETS` (code ``unknown_preset``)."""
    return InputError(f"unknown hairline preset {name!r}; expected one of {', '.join(PRESETS)}", code="unknown_preset")


def check_preset(name: str) -> None:
    """Refuse a preset name not in :data:`PRESETS` (:func:`unknown_preset`)."""
    if name not in PRESETS:
        raise unknown_preset(name)


def parse_preset(spec: str) -> tuple[str, float]:
    """``"NAME"`` or ``"NAME:AMOUNT"`` -> ``(name, amount)``.

    Raises
    ------
    InputError
        Unknown preset, or an amount that is not a number in [0, 1].
    """
    name, _, amount_text = str(spec).partition(":")
    name = name.strip()
    check_preset(name)
    amount = DEFAULT_AMOUNT
    if amount_text.strip():
        try:
            amount = float(amount_text)
        except ValueError:
            raise InputError(f"hairline amount {amount_text!r} is not a number", code="bad_option") from None
    check_amount(amount)
    return name, amount


def check_amount(amount: float) -> None:
    """Refuse an amount outside [0, 1] (or not finite)."""
    if not (np.isfinite(amount) and 0.0 <= amount <= 1.0):
        raise InputError(f"hairline amount must lie in [0, 1], got {amount}", code="bad_option")


def spherical(points: np.ndarray, frame: HeadFrame) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Azimuth, elevation (rad) and distance (m) of ``points (n, 3)`` about the skull centre."""
    rel = np.asarray(points, dtype=np.float64) - frame.centre
    up, forward, side = rel @ frame.up, rel @ frame.forward, rel @ frame.side
    return np.arctan2(side, forward), np.arctan2(up, np.hypot(forward, side)), np.linalg.norm(rel, axis=1)


def direction(theta: np.ndarray, phi: np.ndarray, frame: HeadFrame) -> np.ndarray:
    """(n, 3) unit directions of azimuth ``theta`` and elevation ``phi`` in the head frame."""
    horizontal = np.cos(theta)[:, None] * frame.forward + np.sin(theta)[:, None] * frame.side
    return np.cos(phi)[:, None] * horizontal + np.sin(phi)[:, None] * frame.up


def lateral_position(arc: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """(f,) ``x`` in [-1, 1]: arc length from the midline over the arc length to each end.

    Parameters
    ----------
    arc : (f,) float64
        Non-decreasing arc length along the hairline (m).
    theta : (f,) float64
        Azimuths (rad); the midline is where they first reach 0.
    """
    if not (theta[0] < 0.0 < theta[-1]):
        raise InputError("the front hairline does not run from the right ear across the face to the left ear",
                         code="bad_scalp")
    crossing = int(np.argmax(theta >= 0.0))
    t = -theta[crossing - 1] / (theta[crossing] - theta[crossing - 1])
    middle = arc[crossing - 1] + t * (arc[crossing] - arc[crossing - 1])
    return np.where(arc < middle, (arc - middle) / middle, (arc - middle) / (arc[-1] - middle))


def taper(x: np.ndarray) -> np.ndarray:
    """(f,) 1 on the forehead band, cosine fall to 0 at TAPER_END."""
    t = np.clip((np.abs(x) - BAND) / (TAPER_END - BAND), 0.0, 1.0)
    return 0.5 * (1.0 + np.cos(np.pi * t))


def preset_elevation(name: str, x: np.ndarray, phi0: np.ndarray, radius: float, scale: float) -> np.ndarray:
    """(f,) the full preset's elevation (rad) of each front point (see the module docstring;
    :func:`preset_curve` applies the amount to positions).

    Parameters
    ----------
    name : str
    x : (f,) float64
        Lateral positions.
    phi0 : (f,) float64
        Current elevations (rad).
    radius : float
        ``R``: distance (m) from the skull centre to the hairline.
    scale : float
        Head size relative to REFERENCE_CROWN_M.
    """
    centre = np.abs(x) <= CENTRE
    base = float(np.median(phi0[centre])) if centre.any() else float(np.median(phi0))
    angle = scale / radius  # rad per meter along the head

    def amplitude(meters: float) -> float:
        return meters * angle

    band = x / BAND
    if name == "straight":
        shape = np.full_like(phi0, base)
    elif name == "round":
        shape = base - amplitude(ROUND_DROP_M) * band**2
    elif name == "bell":
        shape = base - amplitude(BELL_DROP_M) * band**4
    elif name == "triangular":
        shape = base + amplitude(TRIANGULAR_RISE_M) * (0.5 - np.abs(band))
    elif name == "widows-peak":
        shape = base - amplitude(WIDOWS_PEAK_DEPTH_M) * np.maximum(0.0, 1.0 - np.abs(x) / PEAK)
    elif name == "m-shape":
        shape = base + amplitude(M_SHAPE_RECESSION_M) * np.exp(-(((np.abs(x) - M_CENTRE) / M_WIDTH) ** 2))
    elif name == "receding":
        shape = phi0 + amplitude(RECEDING_M) * (0.7 + 0.3 * band**2)
    elif name == "sideburns":
        low, high = SIDEBURNS_SPAN
        t = np.clip((np.abs(x) - low) / (high - low), 0.0, 1.0)
        return phi0 - amplitude(SIDEBURNS_LENGTH_M) * np.sin(np.pi * t) ** 2
    else:
        raise unknown_preset(name)
    return phi0 + taper(x) * (shape - phi0)


def preset_curve(name: str, amount: float, front: np.ndarray, turning: np.ndarray, frame: HeadFrame,
                 head: MeshQuery) -> HairlineCurve:
    """The current front hairline edited by a preset.

    Parameters
    ----------
    name : str
        One of :data:`PRESETS`.
    amount : float
        In [0, 1]; 0 returns the current hairline.
    front : (f, 3) float64
        The current front hairline, right ear to left ear (m).
    turning : (t,) int64
        Its turning points (indices into ``front``).
    frame : HeadFrame
    head : MeshQuery
        The head surface the new points are cast onto (the region around the scalp).

    Returns
    -------
    curve : HairlineCurve
        ``f`` points, the same turning points.

    Raises
    ------
    InputError
        Unknown preset, bad amount, or an edit that leaves the head region.
    """
    check_amount(amount)
    front = np.asarray(front, dtype=np.float64)
    turning = np.asarray(turning, dtype=np.int64).copy()
    if amount == 0.0:
        return HairlineCurve(front.copy(), turning)
    smooth = smooth_polyline(front)
    theta0, phi0, distance = spherical(smooth, frame)
    x = lateral_position(polyline_arc_length(smooth), theta0)
    scale = frame.crown / REFERENCE_CROWN_M
    phi = preset_elevation(name, x, phi0, float(np.median(distance)), scale)
    theta = theta0
    if name not in OFFSET_PRESETS:
        # even azimuths across the band, the current ones beyond it, blended by the taper
        ends = np.interp([-BAND, BAND], x, theta0)
        even = ends[0] + (x + BAND) * (ends[1] - ends[0]) / (2 * BAND)
        theta = theta0 + taper(x) * (even - theta0)
    shaped = head.signed_distance(smooth).closest
    moved = np.flatnonzero((np.abs(phi - phi0) > UNMOVED_RAD) | (np.abs(theta - theta0) > UNMOVED_RAD))
    if len(moved):
        rays = direction(theta[moved], phi[moved], frame)
        hits = head.first_hits(np.repeat(frame.centre[None, :], len(moved), axis=0), rays)
        if not hits.hit.all():
            raise InputError(
                f"the {name} hairline leaves the head region around the scalp "
                f"({int((~hits.hit).sum())} of {len(moved)} moved points)",
                code="hairline_off_head",
            )
        shaped[moved] = hits.points
    # keep the hairline's detail across the curve (its staircase), drop it along the curve
    tangent = np.gradient(smooth, axis=0)
    tangent /= np.maximum(np.linalg.norm(tangent, axis=1, keepdims=True), np.finfo(float).tiny)
    detail = front - smooth
    across = detail - np.einsum("ij,ij->i", detail, tangent)[:, None] * tangent
    points = head.signed_distance(front + amount * (shaped + across - front)).closest
    points[[0, -1]] = front[[0, -1]]
    return HairlineCurve(points, turning)
