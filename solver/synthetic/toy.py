"""A small synthetic rigged upper body ("toy" character) for fast tests.

The mesh is one deformed template: a stack of ``TOY_RINGS`` horizontal elliptical rings of
``TOY_RING_VERTICES`` vertices each, closed by a bottom and a top pole vertex. Every ring is
an ellipse that bounds, at its height, the union of three smooth components (torso with a
rounded bottom and rounded shoulders, a neck cylinder, an ellipsoidal head), blended with a
polynomial smooth maximum; a Gaussian nose bump marks the face. Only the vertex positions
depend on the parameters, so every parameter choice gives the same vertex count and the same
faces (what hairport requires of a source/target pair).

Because ring heights strictly increase from the bottom pole to the top pole and every ring
is a simple closed curve, the surface is closed, watertight and free of self-intersections.
Rings are spaced evenly in (weighted) arc length of the profile, so the tessellation adapts
to the parameters.

Conventions: meters, Y up, the face looks along +Z, the character's left is +X (bones
``*_l`` sit at ``x > 0``), faces counter-clockwise seen from outside.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from hairport.solver.model.character import Character, Skeleton

#: vertices per horizontal ring of the template
TOY_RING_VERTICES = 48
#: number of rings between the two poles
TOY_RINGS = 80
#: samples of the profile used to place the rings by arc length
PROFILE_SAMPLES = 4000
#: blending radius (m) of the polynomial smooth maximum joining torso, neck and head
SMOOTH_MAX_RADIUS_M = 0.02
#: ring density on the head relative to the body (more rings where hair grows)
HEAD_RING_DENSITY = 2.0

#: default head half-axes (m): x (ear to ear), y (chin to crown), z (back to face)
HEAD_HALF_AXES_M = (0.09, 0.12, 0.10)
#: height (m) of the bottom of the torso (the template's lowest ring region)
TORSO_BOTTOM_Y_M = 1.15
#: height (m) of the top of the torso dome (shoulder line at the neck)
TORSO_TOP_Y_M = 1.48
#: height (m) of the rounded bottom cap of the torso
TORSO_BOTTOM_CAP_M = 0.04
#: height (m) of the rounded shoulder cap of the torso
SHOULDER_CAP_M = 0.10
#: superellipse exponent of the shoulder cap (2 = elliptical, larger = squarer shoulders)
SHOULDER_EXPONENT = 3.0
#: head joint (top of the neck bone) below the skull centre, as a fraction of the head half-height
HEAD_JOINT_BELOW_CENTRE = 0.25
#: head bone tail above the skull centre, as a fraction of the head half-height
HEAD_TAIL_ABOVE_CENTRE = 0.9
#: head/neck skin-weight transition below the skull centre, as a fraction of the head half-height
HEAD_WEIGHT_BELOW_CENTRE = 0.6
#: nose: height above the skull centre (fraction of half-height), size (m)
NOSE_HEIGHT_FRACTION = -0.35
NOSE_PROTRUSION_M = 0.018
NOSE_HALF_WIDTH_M = 0.012
NOSE_HALF_LENGTH_M = 0.022

#: bone names, MakeHuman game-engine rig spelling
TOY_BONES = ("spine_03", "neck_01", "head", "clavicle_l", "clavicle_r", "upperarm_l", "upperarm_r")
TOY_PARENTS = (-1, 0, 1, 0, 0, 3, 4)

ABSENT = -1.0  # width of a component at heights it does not occupy (m, loses every smooth max)


def toy_character(
    head_scale: tuple[float, float, float] = (1.0, 1.0, 1.0),
    neck_radius: float = 0.055,
    neck_length: float = 0.13,
    shoulder_width: float = 0.38,
    chest_depth: float = 0.22,
    head_forward: float = 0.01,
    nose: bool = True,
    name: str = "toy",
) -> Character:
    """A rigged, watertight upper body of fixed topology.

    Parameters
    ----------
    head_scale : (3,) float
        Multiplies the default head half-axes ``HEAD_HALF_AXES_M`` (x, y, z).
    neck_radius : float
        Meters.
    neck_length : float
        Meters from the top of the torso dome to the head joint.
    shoulder_width : float
        Meters, full width of the torso at the shoulders.
    chest_depth : float
        Meters, full front-to-back depth of the torso.
    head_forward : float
        Meters the skull centre sits in front of the neck axis (+Z).
    nose : bool
        Add a nose bump on the face (vertex positions only; topology unchanged).
    name : str

    Returns
    -------
    character : Character
        ``TOY_RINGS * TOY_RING_VERTICES + 2`` vertices, faces identical for every parameter
        choice; skeleton with bones ``TOY_BONES``; skin weights (V, B) with rows summing to 1.
    """
    ax, ay, az = (np.asarray(HEAD_HALF_AXES_M) * np.asarray(head_scale, dtype=np.float64)).tolist()
    if min(ax, ay, az, neck_radius, neck_length, shoulder_width, chest_depth) <= 0:
        raise ValueError("toy_character: sizes must be positive")
    half_width = shoulder_width / 2.0
    half_depth = chest_depth / 2.0
    neck_z = -0.01
    head_z = neck_z + head_forward
    head_joint_y = TORSO_TOP_Y_M + neck_length
    head_y = head_joint_y + HEAD_JOINT_BELOW_CENTRE * ay
    shape = _Shape(
        half_width=half_width,
        half_depth=half_depth,
        neck_radius=neck_radius,
        neck_z=neck_z,
        neck_bottom=TORSO_TOP_Y_M - 0.08,
        neck_top=head_y,
        head_centre=np.array([0.0, head_y, head_z]),
        head_axes=np.array([ax, ay, az]),
    )
    vertices, faces = _tessellate(shape, nose)

    # skeleton
    neck_base = np.array([0.0, TORSO_TOP_Y_M - 0.02, neck_z])
    head_joint = np.array([0.0, head_joint_y, 0.5 * (neck_z + head_z)])
    centre = shape.head_centre
    head_tail = head_joint + (centre - head_joint) * (
        (HEAD_JOINT_BELOW_CENTRE + HEAD_TAIL_ABOVE_CENTRE) / HEAD_JOINT_BELOW_CENTRE
    )
    top = TORSO_TOP_Y_M
    heads = np.array(
        [
            [0.0, TORSO_BOTTOM_Y_M + 0.10, 0.0],
            neck_base,
            head_joint,
            [0.1 * half_width, top - 0.04, 0.02],
            [-0.1 * half_width, top - 0.04, 0.02],
            [0.8 * half_width, top - 0.06, 0.0],
            [-0.8 * half_width, top - 0.06, 0.0],
        ]
    )
    tails = np.array(
        [
            [0.0, top - 0.05, 0.0],
            head_joint,
            head_tail,
            [0.8 * half_width, top - 0.06, 0.0],
            [-0.8 * half_width, top - 0.06, 0.0],
            [0.95 * half_width, top - 0.16, 0.0],
            [-0.95 * half_width, top - 0.16, 0.0],
        ]
    )
    skeleton = Skeleton(TOY_BONES, np.array(TOY_PARENTS), heads, tails)
    weights = _skin_weights(vertices, neck_base[1], head_y - HEAD_WEIGHT_BELOW_CENTRE * ay, half_width)
    return Character(vertices, faces, skeleton, weights, name)


class _Shape:
    """Cross-section extents of the toy body as functions of height."""

    def __init__(self, *, half_width, half_depth, neck_radius, neck_z, neck_bottom, neck_top, head_centre, head_axes):
        self.half_width = half_width
        self.half_depth = half_depth
        self.neck_radius = neck_radius
        self.neck_z = neck_z
        self.neck_bottom = neck_bottom
        self.neck_top = neck_top
        self.head_centre = head_centre
        self.head_axes = head_axes
        self.y_min = TORSO_BOTTOM_Y_M
        self.y_max = head_centre[1] + head_axes[1]

    def extents(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Half-width in x, lowest and highest z of the cross-section at heights ``y (n,)``."""
        # torso: rounded bottom cap, straight sides, elliptical shoulder cap
        bottom_cap_top = TORSO_BOTTOM_Y_M + TORSO_BOTTOM_CAP_M
        shoulder_start = TORSO_TOP_Y_M - SHOULDER_CAP_M
        factor = np.ones_like(y)
        low = y < bottom_cap_top
        factor[low] = _circle_profile((bottom_cap_top - y[low]) / TORSO_BOTTOM_CAP_M)
        high = y > shoulder_start
        factor[high] = _superellipse_profile((y[high] - shoulder_start) / SHOULDER_CAP_M, SHOULDER_EXPONENT)
        torso_present = (y >= TORSO_BOTTOM_Y_M) & (y <= TORSO_TOP_Y_M)
        torso_w = np.where(torso_present, self.half_width * factor, ABSENT)
        torso_d = np.where(torso_present, self.half_depth * factor, ABSENT)

        # neck: a cylinder whose top tapers to nothing inside the head
        taper_start = self.neck_top - 0.03
        neck_factor = np.ones_like(y)
        over = y > taper_start
        neck_factor[over] = _circle_profile((y[over] - taper_start) / 0.03)
        neck_present = (y >= self.neck_bottom) & (y <= self.neck_top)
        neck_w = np.where(neck_present, self.neck_radius * neck_factor, ABSENT)

        # head: ellipsoid slices
        cx, cy, cz = self.head_centre
        hx, hy, hz = self.head_axes
        t = (y - cy) / hy
        head_present = np.abs(t) <= 1.0
        head_factor = _circle_profile(np.clip(t, -1.0, 1.0))
        head_w = np.where(head_present, hx * head_factor, ABSENT)
        head_d = np.where(head_present, hz * head_factor, ABSENT)

        k = SMOOTH_MAX_RADIUS_M
        width = _smooth_max(_smooth_max(torso_w, neck_w, k), head_w, k)
        # z extents: absent components must not win, so give them a far-away value
        far = -10.0
        z_hi = _smooth_max(
            _smooth_max(np.where(torso_present, torso_d, far), np.where(neck_present, self.neck_z + neck_w, far), k),
            np.where(head_present, cz + head_d, far),
            k,
        )
        z_lo = -_smooth_max(
            _smooth_max(np.where(torso_present, torso_d, far), np.where(neck_present, -self.neck_z + neck_w, far), k),
            np.where(head_present, -cz + head_d, far),
            k,
        )
        return np.maximum(width, 0.0), z_lo, z_hi


def _superellipse_profile(t: np.ndarray, exponent: float) -> np.ndarray:
    return np.clip(1.0 - np.abs(t) ** exponent, 0.0, 1.0) ** (1.0 / exponent)


def _circle_profile(t: np.ndarray) -> np.ndarray:
    return np.sqrt(np.clip(1.0 - t * t, 0.0, 1.0))


def _smooth_max(a: np.ndarray, b: np.ndarray, k: float) -> np.ndarray:
    """Polynomial smooth maximum: equals ``max(a, b)`` where ``|a - b| >= k``, C1 everywhere."""
    h = np.maximum(k - np.abs(a - b), 0.0)
    return np.maximum(a, b) + h * h / (4.0 * k)


def _smoothstep(x: np.ndarray, lo: float, hi: float) -> np.ndarray:
    t = np.clip((x - lo) / (hi - lo), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _tessellate(shape: _Shape, nose: bool) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) and faces (F, 3) of the ring template for ``shape``."""
    m, r = TOY_RING_VERTICES, TOY_RINGS
    y = np.linspace(shape.y_min, shape.y_max, PROFILE_SAMPLES)
    width, z_lo, z_hi = shape.extents(y)
    ds = np.sqrt(np.diff(y) ** 2 + np.diff(width) ** 2 + 0.5 * (np.diff(z_lo) ** 2 + np.diff(z_hi) ** 2))
    mid = 0.5 * (y[1:] + y[:-1])
    density = 1.0 + (HEAD_RING_DENSITY - 1.0) * _smoothstep(mid, shape.neck_top - 0.12, shape.neck_top - 0.06)
    s = np.concatenate([[0.0], np.cumsum(ds * density)])
    ring_s = s[-1] * np.arange(1, r + 1) / (r + 1)
    ring_y = np.interp(ring_s, s, y)
    ring_w, ring_lo, ring_hi = shape.extents(ring_y)
    ring_zc = 0.5 * (ring_lo + ring_hi)
    ring_d = 0.5 * (ring_hi - ring_lo)

    theta = 2.0 * np.pi * np.arange(m) / m
    x = ring_w[:, None] * np.cos(theta)[None]
    z = ring_zc[:, None] + ring_d[:, None] * np.sin(theta)[None]
    yy = np.broadcast_to(ring_y[:, None], x.shape)
    if nose:
        cy = shape.head_centre[1] + NOSE_HEIGHT_FRACTION * shape.head_axes[1]
        front = np.maximum(np.sin(theta), 0.0)[None] ** 4
        bump = np.exp(-((x / NOSE_HALF_WIDTH_M) ** 2) - ((yy - cy) / NOSE_HALF_LENGTH_M) ** 2)
        z = z + NOSE_PROTRUSION_M * bump * front
    ring_vertices = np.stack([x, yy, z], axis=-1).reshape(-1, 3)
    bottom = np.array([[0.0, shape.y_min, float(np.interp(shape.y_min, y, 0.5 * (z_lo + z_hi)))]])
    top = np.array([[0.0, shape.y_max, shape.head_centre[2]]])
    vertices = np.concatenate([ring_vertices, bottom, top])
    return vertices, _template_faces()


def _template_faces() -> np.ndarray:
    """(F, 3) int64 faces of the ring template, outward (counter-clockwise from outside)."""
    m, r = TOY_RING_VERTICES, TOY_RINGS
    k, j = np.meshgrid(np.arange(r - 1), np.arange(m), indexing="ij")
    k, j = k.ravel(), j.ravel()
    a = k * m + j
    b = k * m + (j + 1) % m
    c = (k + 1) * m + j
    d = (k + 1) * m + (j + 1) % m
    side = np.concatenate([np.stack([a, c, b], 1), np.stack([b, c, d], 1)])
    bottom_pole, top_pole = r * m, r * m + 1
    j = np.arange(m)
    bottom = np.stack([np.full(m, bottom_pole), j, (j + 1) % m], 1)
    last = (r - 1) * m
    top = np.stack([np.full(m, top_pole), last + (j + 1) % m, last + j], 1)
    return np.concatenate([side, bottom, top]).astype(np.int64)


def _skin_weights(vertices: np.ndarray, neck_base_y: float, head_start_y: float, half_width: float) -> sp.csr_matrix:
    """Smooth partition-of-unity skin weights (V, B) for ``TOY_BONES``.

    Along the body axis the weight passes from spine to neck around the neck base and from
    neck to head at the jaw and nape (``head_start_y``); the torso part is split sideways between spine,
    clavicles (mid shoulder) and upper arms (shoulder edge).
    """
    x, y = vertices[:, 0], vertices[:, 1]
    blend = 0.015  # m, half-width of the axial transitions
    head = _smoothstep(y, head_start_y - blend, head_start_y + blend)
    neck_or_head = _smoothstep(y, neck_base_y - 2 * blend, neck_base_y + blend)
    neck = (1.0 - head) * neck_or_head
    torso = (1.0 - head) * (1.0 - neck_or_head)
    ax = np.abs(x) / half_width
    arm = _smoothstep(ax, 0.7, 0.9)
    clav = _smoothstep(ax, 0.25, 0.5) * (1.0 - arm)
    spine = 1.0 - arm - clav
    left = x > 0
    w = np.zeros((len(vertices), len(TOY_BONES)))
    w[:, 0] = torso * spine
    w[:, 1] = neck
    w[:, 2] = head
    w[:, 3] = torso * clav * left
    w[:, 4] = torso * clav * ~left
    w[:, 5] = torso * arm * left
    w[:, 6] = torso * arm * ~left
    w[w < 1e-9] = 0.0
    w /= w.sum(axis=1, keepdims=True)
    return sp.csr_matrix(w)
