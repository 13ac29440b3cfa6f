"""Procedural grooms: strands grown from the scalp of any rigged character.

The generator works on any :class:`~hairport.solver.model.character.Character` whose
skeleton has a ``head`` bone and (ideally) skin weights: the toy character of
:mod:`hairport.solver.synthetic.toy` for fast tests, and the MakeHuman body (game-engine rig)
for demos and benchmarks. Conventions: meters, Y up, the face looks along +Z.

Pipeline (:func:`generate_groom`):

1. **Head frame** (:func:`hairport.solver.body.head_frame.head_frame`): up axis, head
   joint, crown height, front and back extents and half-width of the head.
2. **Scalp** (:func:`scalp_faces`): head-dominant faces above a plane tilted from the
   front hairline (high, above the forehead) over the ears to the nape (low).
3. **Roots** (:func:`sample_roots`): area-weighted random points on scalp faces (face +
   barycentric, exactly on the surface), seeded.
4. **Growth**, vectorised over all strands, a Python loop over the particle steps only:
   the first segment leaves along the surface normal; each later direction blends the
   previous direction, gravity (-Y), a per-style "comb" direction (projected onto the
   local tangent plane near the body) and a pull toward the body that makes strands
   drape. Step length = length / (particles - 1). Wavy and curly styles add a sinusoidal
   (planar) or helical offset perpendicular to the growth direction. After every step
   the new particles closer to the body than ``clearance`` are pushed out along the
   distance normal to ``clearance``
   (:meth:`hairport.solver.mesh.query.MeshQuery.signed_distance`; one query per step,
   since each query has a fixed cost).
5. A final check over all particles pushes out any particle still below ``clearance``
   (repeated normal pushes; particles stuck in crevices narrower than twice the clearance,
   such as behind a MakeHuman ear, move away from the skull centre), so every non-root
   particle ends at signed distance >= ``clearance`` on the source body.

Default lengths are for an adult head and scale with its size (``REFERENCE_CROWN_M``).
Curls need resolution: at the default period, ``curly`` shows round curls from about 48
particles per strand; below that the period is stretched to ``MIN_SEGMENTS_PER_PERIOD``
segments and curls turn into zig-zags.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hairport.solver.body.head_frame import REFERENCE_CROWN_M, HeadFrame, head_frame
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.mesh.triangles import interpolate_barycentric
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import Hair

#: default distance (m) every non-root particle keeps from the body
DEFAULT_CLEARANCE_M = 3e-3

#: scalp boundary: normalised height (0 = head joint, 1 = crown) at the front and the back
HAIRLINE_FRONT_HEIGHT = 0.64
HAIRLINE_BACK_HEIGHT = 0.02
#: normalised height of the jaw line (0 = head joint, 1 = crown)
JAW_HEIGHT = -0.35

#: pushes overshoot the clearance by this much (m), to avoid re-pushing on round-off
PUSH_MARGIN_M = 1e-7
#: normal pushes in the final clearance pass before stuck particles escape radially
MAX_PUSH_ITERATIONS = 8
#: farthest (m) a stuck particle moves away from the skull centre to get clear
ESCAPE_LIMIT_M = 0.3
#: distance (m) under which strands feel the body (tangential comb, pull toward it)
NEAR_BODY_M = 0.015
#: gravity's weight rises to its full value over about this arc length (m) from the root
GRAVITY_ONSET_M = 0.03

#: the hairstyles :func:`generate_groom` grows
STYLES = ("short", "long", "wavy", "curly", "fringe")

#: default strand lengths (m): mean and relative spread (uniform, +-)
SHORT_LENGTH_RANGE_M = (0.03, 0.06)
LONG_LENGTH_M = 0.40
WAVY_LENGTH_M = 0.32
CURLY_LENGTH_M = 0.26
FRINGE_BACK_LENGTH_M = 0.14
LENGTH_SPREAD = 0.12
#: wave: amplitude (m) and period (m, along the strand)
WAVY_AMPLITUDE_M = 0.010
WAVY_PERIOD_M = 0.06
#: curl: helix radius (m) and period (m, along the strand)
CURLY_AMPLITUDE_M = 0.009
CURLY_PERIOD_M = 0.035
#: waves and curls stay resolved: the period is raised to at least this many segments
MIN_SEGMENTS_PER_PERIOD = 5.0
#: offsets ramp up over this length (m) from the root
WAVE_RAMP_M = 0.04
#: arc length (m) over which the comb direction fades (long/wavy/curly, bob, fringe)
LONG_COMB_DECAY_M = 0.08
BOB_COMB_DECAY_M = 0.06
FRINGE_COMB_DECAY_M = 0.04
#: fringe tips end this far (m) below the brows
FRINGE_BELOW_BROW_M = 0.015


def scalp_faces(character: Character, frame: HeadFrame | None = None) -> np.ndarray:
    """Faces where hair grows.

    A face is scalp when its three vertices are head-dominant and its centroid lies above
    the plane through the front hairline (``HAIRLINE_FRONT_HEIGHT`` of the crown height,
    above the forehead) and the nape (``HAIRLINE_BACK_HEIGHT``), which passes just above the
    ears on the sides. No vertex ids are hard-coded.

    Parameters
    ----------
    character : Character
    frame : HeadFrame, optional
        Reuse a frame from :func:`head_frame`.

    Returns
    -------
    faces : (K,) int64
        Indices into ``character.faces``, ascending.
    """
    frame = frame or head_frame(character)
    faces = character.faces
    all_head = frame.head_vertices[faces].all(axis=1)
    centroid = character.vertices[faces].mean(axis=1)
    eta, g, _ = frame.normalised(centroid).T
    line = HAIRLINE_BACK_HEIGHT + (HAIRLINE_FRONT_HEIGHT - HAIRLINE_BACK_HEIGHT) * 0.5 * (np.clip(g, -1, 1) + 1.0)
    scalp = np.flatnonzero(all_head & (eta > line))
    if len(scalp) == 0:
        raise InputError("found no scalp faces on the head", character.name, "no_scalp")
    return scalp.astype(np.int64)


def sample_roots(
    character: Character, faces: np.ndarray, n: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Area-weighted random points on the given faces.

    Parameters
    ----------
    character : Character
    faces : (K,) int64
        Candidate faces.
    n : int
    rng : numpy Generator

    Returns
    -------
    face_ids : (n,) int64
    barycentric : (n, 3) float64
    points : (n, 3) float64
    """
    corners = character.vertices[character.faces[faces]]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    face_ids = faces[rng.choice(len(faces), size=n, p=area / area.sum())]
    r1, r2 = rng.random(n), rng.random(n)
    root = np.sqrt(r1)
    barycentric = np.stack([1.0 - root, root * (1.0 - r2), root * r2], axis=1)
    points = interpolate_barycentric(character.vertices, character.faces, face_ids, barycentric)
    return face_ids.astype(np.int64), barycentric, points


@dataclass
class _StrandPlan:
    """Per-strand growth parameters, all arrays over the S strands."""

    length: np.ndarray  # (S,) m
    comb: np.ndarray  # (S, 3) unit, preferred direction near the root
    comb_weight: np.ndarray  # (S,)
    comb_decay: np.ndarray  # (S,) m, arc length over which the comb fades
    gravity: np.ndarray  # (S,)
    hug: np.ndarray  # (S,) pull toward the body when near it
    tangent_comb: np.ndarray | None = None  # (S,) bool, comb projected onto the root's tangent plane (default all)
    wave: str = "none"  # none | planar | helix
    amplitude: np.ndarray | None = None  # (S,) m
    period: np.ndarray | None = None  # (S,) m
    phase: np.ndarray | None = None  # (S,) rad


def generate_groom(
    character: Character,
    style: str,
    n_strands: int,
    particles_per_strand: int,
    seed: int = 0,
    *,
    length: float | None = None,
    clearance: float = DEFAULT_CLEARANCE_M,
    amplitude: float | None = None,
    period: float | None = None,
    query: MeshQuery | None = None,
) -> Hair:
    """Grow a procedural hairstyle on a rigged character.

    Parameters
    ----------
    character : Character
        Needs a skeleton with a ``head`` bone (skin weights recommended).
    style : str
        ``short`` (3-6 cm, following the scalp), ``long`` (parted, falling over the head down
        the back and onto the shoulders), ``wavy`` / ``curly`` (long-ish with a planar
        sinusoidal / helical offset perpendicular to the growth direction), ``fringe``
        (fringe over the forehead to the brows, strands down the cheeks in front of the ears,
        a bob on the rest of the scalp).
    n_strands : int
        S >= 1.
    particles_per_strand : int
        P >= 2.
    seed : int
        Same seed, same arrays.
    length : float, optional
        Mean strand length in meters (jittered by +-``LENGTH_SPREAD``). Defaults per style;
        for ``short`` it replaces the 3-6 cm range by length +-``LENGTH_SPREAD``; for
        ``fringe`` it is the length of the back strands (fringe and cheek strands get lengths
        that reach the brows and the jaw).
    clearance : float
        Meters: every non-root particle ends at least this far outside the body.
    amplitude, period : float, optional
        Wave amplitude / curl radius and period (m along the strand) for ``wavy`` and
        ``curly``; the period is raised to ``MIN_SEGMENTS_PER_PERIOD`` segments if needed.
    query : MeshQuery, optional
        Reuse acceleration structures over ``character``.

    Returns
    -------
    hair : Hair
        S strands of exactly P particles, root first, roots on the scalp surface.
    """
    if style not in STYLES:
        raise InputError(f"unknown groom style {style!r}; expected one of {', '.join(STYLES)}", code="bad_style")
    if n_strands < 1 or particles_per_strand < 2:
        raise InputError("need n_strands >= 1 and particles_per_strand >= 2", code="bad_groom")
    if clearance <= 0:
        raise InputError("clearance must be positive", code="bad_groom")
    rng = np.random.default_rng(seed)
    frame = head_frame(character)
    scalp = scalp_faces(character, frame)
    face_ids, _, roots = sample_roots(character, scalp, n_strands, rng)
    query = query or MeshQuery(character.vertices, character.faces)
    normals = _root_normals(character, face_ids, roots)
    plan = _plan(style, frame, roots, particles_per_strand, rng, length, amplitude, period)
    points = _grow(query, roots, normals, plan, particles_per_strand, clearance, frame)
    offsets = np.arange(n_strands + 1, dtype=np.int64) * particles_per_strand
    return Hair(points.reshape(-1, 3), offsets)


def _root_normals(character: Character, face_ids: np.ndarray, roots: np.ndarray) -> np.ndarray:
    """(S, 3) outward unit normal at the roots (the distance field's pseudonormal direction,
    smoothed by the area-weighted vertex normals of the face)."""
    v, f = character.vertices, character.faces
    face_normal = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    vertex_normal = np.zeros_like(v)
    for k in range(3):
        np.add.at(vertex_normal, f[:, k], face_normal)
    vertex_normal /= np.maximum(np.linalg.norm(vertex_normal, axis=1, keepdims=True), 1e-300)
    own = face_normal[face_ids] / np.linalg.norm(face_normal[face_ids], axis=1, keepdims=True)
    smooth = vertex_normal[f[face_ids]].mean(axis=1)
    n = own + smooth
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _unit(v: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(norm > 1e-300, norm, 1.0)


def _jittered(mean: float, n: int, rng: np.random.Generator) -> np.ndarray:
    return mean * rng.uniform(1.0 - LENGTH_SPREAD, 1.0 + LENGTH_SPREAD, n)


def _plan(style, frame: HeadFrame, roots, p, rng, length, amplitude, period) -> _StrandPlan:
    """Per-strand lengths, comb directions and weights for one style.

    Weights are unitless and relative to the previous direction (weight 1); lengths and
    decay lengths scale with the head (``frame.crown / REFERENCE_CROWN_M``).
    """
    s = len(roots)
    eta, g, sigma = frame.normalised(roots).T
    up, fwd, side = frame.up, frame.forward, frame.side
    scale = frame.crown / REFERENCE_CROWN_M
    jitter = 0.15 * rng.standard_normal((s, 3))
    ones = np.ones(s)
    # parted hair: away from the middle parting, backward, a little down
    sideways = np.sign(sigma + 1e-12)[:, None] * side
    parted = _unit(sideways * 0.9 - fwd * 0.8 - up * 0.5 + jitter)  # combed back
    # more over the shoulders, and downward except near the front hairline (where "down"
    # would comb the hair over the face)
    down = 0.3 + 0.9 * np.clip((0.6 - g) / 0.4, 0.0, 1.0)
    parted_open = _unit(sideways * 0.9 - fwd * 0.35 - up * down[:, None] + jitter)
    if style == "short":
        lo, hi = SHORT_LENGTH_RANGE_M
        lengths = rng.uniform(lo, hi, s) if length is None else _jittered(length, s, rng)
        # swept back and sideways from the parting, lying on the scalp
        comb = parted
        return _StrandPlan(lengths, comb, 2.0 * ones, np.inf * ones, 0.3 * ones, 1.5 * ones)
    if style in ("long", "wavy", "curly"):
        mean = {"long": LONG_LENGTH_M, "wavy": WAVY_LENGTH_M, "curly": CURLY_LENGTH_M}[style]
        lengths = _jittered(length if length is not None else mean * scale, s, rng)
        plan = _StrandPlan(lengths, parted_open, 1.5 * ones, LONG_COMB_DECAY_M * scale * ones, 1.0 * ones, 0.1 * ones)
        if style == "long":
            return plan
        step = lengths / (p - 1)
        if style == "wavy":
            plan.wave = "planar"
            amp = WAVY_AMPLITUDE_M if amplitude is None else amplitude
            per = WAVY_PERIOD_M if period is None else period
            plan.phase = 0.3 * rng.standard_normal(s)
        else:
            plan.wave = "helix"
            amp = CURLY_AMPLITUDE_M if amplitude is None else amplitude
            per = CURLY_PERIOD_M if period is None else period
            plan.phase = rng.uniform(0.0, 2.0 * np.pi, s)
        plan.amplitude = amp * rng.uniform(0.8, 1.2, s)
        plan.period = np.maximum(per * rng.uniform(0.9, 1.1, s), MIN_SEGMENTS_PER_PERIOD * step)
        return plan
    # fringe: forehead fringe, cheek strands in front of the ears, a bob behind
    a = eta * frame.crown
    fringe = (g > 0.45) & (np.abs(sigma) < 0.5)
    cheek = ~fringe & (g > 0.1) & (np.abs(sigma) >= 0.5)
    back = ~fringe & ~cheek
    lengths = np.empty(s)
    comb = parted.copy()
    comb_weight = 1.5 * ones
    comb_decay = BOB_COMB_DECAY_M * scale * ones
    gravity = 1.0 * ones
    hug = 0.1 * ones
    # fringe strands go forward, then fall in front of the forehead to just below the brows
    target = frame.brow_height - FRINGE_BELOW_BROW_M * scale
    lengths[fringe] = 1.05 * (a[fringe] - target) + 0.015 * scale
    comb[fringe] = _unit(fwd + 0.1 * up + 0.2 * np.sign(sigma[fringe])[:, None] * side + 0.2 * jitter[fringe])
    comb_weight[fringe] = 0.5
    comb_decay[fringe] = FRINGE_COMB_DECAY_M * scale
    hug[fringe] = 0.0
    tangent_comb = ~fringe
    # cheek strands fall down the temples and cheeks, slightly forward
    jaw = JAW_HEIGHT * frame.crown
    lengths[cheek] = 1.15 * (a[cheek] - jaw) + 0.02 * scale
    comb[cheek] = _unit(-up + 0.5 * fwd + 0.3 * np.sign(sigma[cheek])[:, None] * side + 0.3 * jitter[cheek])
    comb_weight[cheek] = 1.0
    hug[cheek] = 0.5
    mean = FRINGE_BACK_LENGTH_M * scale if length is None else length
    lengths[back] = _jittered(mean, int(back.sum()), rng)
    lengths *= rng.uniform(1.0 - LENGTH_SPREAD / 2, 1.0 + LENGTH_SPREAD / 2, s)
    lengths = np.maximum(lengths, 0.02 * scale)
    return _StrandPlan(lengths, comb, comb_weight, comb_decay, gravity, hug, tangent_comb)


def _push_once(query: MeshQuery, points: np.ndarray, clearance: float):
    """One query; points closer than ``clearance`` move out along the distance normal.

    Returns
    -------
    points : (n, 3) float64
        Pushed copy (not re-checked: concave spots may need more, see :func:`_enforce_clearance`).
    distance : (n,) float64
        Signed distance, ``clearance`` assumed for pushed points.
    normal : (n, 3) float64
        Distance normal before the push.
    """
    points = points.copy()
    sd = query.signed_distance(points)
    distance = sd.distance.copy()
    low = distance < clearance
    points[low] += (clearance + PUSH_MARGIN_M - distance[low])[:, None] * sd.normal[low]
    distance[low] = clearance
    return points, distance, sd.normal


def _enforce_clearance(query: MeshQuery, points: np.ndarray, clearance: float, escape_from: np.ndarray) -> np.ndarray:
    """Points (n, 3) moved until every one has signed distance >= ``clearance``.

    Repeated pushes along the distance normal first; points stuck in crevices narrower than
    twice the clearance (e.g. between an ear and the head) then move away from
    ``escape_from`` (3,) by growing distances (x1.5 each try) until they are clear.

    Raises
    ------
    RuntimeError
        If some point cannot be cleared (never seen on closed meshes).
    """
    points = points.copy()
    sd = query.signed_distance(points)
    todo = np.flatnonzero(sd.distance < clearance)
    distance, normal = sd.distance[todo], sd.normal[todo]
    for _ in range(MAX_PUSH_ITERATIONS):
        if len(todo) == 0:
            return points
        points[todo] += (clearance + PUSH_MARGIN_M - distance)[:, None] * normal
        sd = query.signed_distance(points[todo])
        low = sd.distance < clearance
        todo, distance, normal = todo[low], sd.distance[low], sd.normal[low]
    start = points[todo]
    away = _unit(start - escape_from)
    shift = clearance
    while len(todo) and shift < ESCAPE_LIMIT_M:
        candidate = start + shift * away
        sd = query.signed_distance(candidate)
        clear = sd.distance >= clearance
        points[todo[clear]] = candidate[clear]
        todo, start, away = todo[~clear], start[~clear], away[~clear]
        shift *= 1.5
    if len(todo):
        raise RuntimeError(f"groom: {len(todo)} particles could not be moved outside the clearance")
    return points


def _grow(query: MeshQuery, roots, normals, plan: _StrandPlan, p: int, clearance: float, frame: HeadFrame) -> np.ndarray:
    """(S, P, 3) particle positions, grown step by step for all strands at once."""
    s = len(roots)
    gravity_dir = np.array([0.0, -1.0, 0.0])
    step = plan.length / (p - 1)
    out = np.empty((s, p, 3))
    out[:, 0] = roots
    centre = roots.copy()  # wave-free centreline
    direction = normals.copy()
    surface_normal = normals.copy()
    distance = np.zeros(s)
    # comb directions, made tangent to the scalp at the root where asked
    tangent = np.ones(s, dtype=bool) if plan.tangent_comb is None else plan.tangent_comb
    along = (plan.comb * normals).sum(1, keepdims=True) * normals
    comb_dir = _unit(np.where(tangent[:, None], plan.comb - along, plan.comb))
    # frame for wave offsets, transported along the strand
    ref = np.where((np.abs(normals @ frame.side) < 0.9)[:, None], frame.side, frame.forward)
    b1 = _unit(ref - (ref * normals).sum(1, keepdims=True) * normals)
    for k in range(1, p):
        arc = k * step  # (S,) arc length of the centreline at particle k
        if k > 1:
            near = np.exp(-np.maximum(distance - NEAR_BODY_M, 0.0) / NEAR_BODY_M)[:, None]
            comb = comb_dir - near * (comb_dir * surface_normal).sum(1, keepdims=True) * surface_normal
            w_comb = (plan.comb_weight * np.exp(-arc / plan.comb_decay))[:, None]
            w_grav = (plan.gravity * (1.0 - np.exp(-arc / GRAVITY_ONSET_M)))[:, None]
            hug = -(plan.hug[:, None] * near) * surface_normal
            direction = _unit(direction + w_comb * _unit(comb) + w_grav * gravity_dir + hug)
        new_centre = centre + step[:, None] * direction
        offset = np.zeros((s, 3))
        if plan.wave != "none":
            b1 = _unit(b1 - (b1 * direction).sum(1, keepdims=True) * direction)
            b2 = np.cross(direction, b1)
            ramp = np.clip((arc - step) / WAVE_RAMP_M, 0.0, 1.0)
            ramp = ramp * ramp * (3 - 2 * ramp)
            angle = plan.phase + 2.0 * np.pi * arc / plan.period
            amp = (plan.amplitude * ramp)[:, None]
            if plan.wave == "planar":
                offset = amp * np.sin(angle)[:, None] * b1
            else:
                offset = amp * (np.cos(angle)[:, None] * b1 + np.sin(angle)[:, None] * b2)
        particle = new_centre + offset
        pushed, distance, surface_normal = _push_once(query, particle, clearance)
        new_centre = new_centre + (pushed - particle)
        moved = new_centre - centre
        direction = np.where(
            (np.linalg.norm(moved, axis=1) > 1e-12)[:, None], _unit(moved), direction
        )
        centre = new_centre
        out[:, k] = pushed
    # final guarantee over all non-root particles
    rest = _enforce_clearance(query, out[:, 1:].reshape(-1, 3), clearance, frame.centre)
    out[:, 1:] = rest.reshape(s, p - 1, 3)
    return out
