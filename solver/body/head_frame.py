"""A head-aligned frame from the head bone and the mesh: where up, forward and the skull are.

A character without a rig (most head meshes from DCC tools and scans) gets its frame from the
mesh alone (:func:`mesh_head_frame`): hairport's axes (Y up, the face toward +Z, which loading
infers for files in other axes), the top of the mesh, and proportions measured on the six
MakeHuman presets, whose rigs place the head joint at 0.73-0.85 skull depths below the crown
(mean 0.76) and 0.44-0.51 of the skull's depth in front of its back (mean 0.46)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hairport.solver.mesh.shells import vertex_components
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError

#: a vertex belongs to the head when its normalised head skin weight is at least this
HEAD_WEIGHT_MIN = 0.9
#: normalised height of the brows (0 = head joint, 1 = crown)
BROW_HEIGHT = 0.30
#: crown height (m) above the head joint of the heads the default lengths are made for
#: (MakeHuman base mesh 0.149, toy 0.150); lengths scale with the head
REFERENCE_CROWN_M = 0.15
#: vertices above this normalised height define the skull's front, back and width
SKULL_REFERENCE_HEIGHT = 0.35
#: a rigless head's crown height above its (estimated) head joint, in skull depths, and the
#: joint's place from the back of the skull toward the face, as a share of that depth: the means
#: over the MakeHuman presets' rigs (module docstring)
CROWN_PER_SKULL_DEPTH = 0.76
JOINT_FORWARD_SHARE = 0.46
#: rounds of the rigless estimate (crown height -> skull slice -> depth -> crown height): the
#: MakeHuman heads settle in one, the same heads scaled by 0.5, 2 and 3 in two, three and four
MESH_FRAME_ROUNDS = 6
#: a rigless head's vertices reach this many crown heights below the estimated joint (the face
#: and jaw: the MakeHuman rigs' head-dominant vertices reach 0.26-0.32 at their 5th percentile)
HEAD_BELOW_JOINT_SHARE = 0.3
#: where a head frame comes from
FRAME_FROM_BONE = "head bone"
FRAME_FROM_MESH = "mesh"


@dataclass(frozen=True)
class HeadFrame:
    """A head-aligned frame and the head's extents, derived from the head bone and the mesh.

    Local coordinates of a point ``p``: height ``a = (p - origin) . up``, forward
    ``f = (p - origin) . forward``, sideways ``s = (p - origin) . side``.

    Attributes
    ----------
    origin : (3,) float64
        The head joint (head end of the head bone), meters.
    up, forward, side : (3,) float64
        Unit axes: along the head bone, toward the face (+Z made orthogonal to ``up``),
        toward the character's left (``up x forward``).
    crown : float
        Height ``a`` of the top of the head (m).
    front, back : float
        Largest and smallest ``f`` of the skull above ``SKULL_REFERENCE_HEIGHT`` (m).
    half_width : float
        Largest ``|s|`` of the skull (m).
    head_vertices : (V,) bool
        Head-dominant vertices of the connected piece of the mesh that holds most of them.
    source : str
        :data:`FRAME_FROM_BONE` or :data:`FRAME_FROM_MESH` (a character without a rig).
    """

    origin: np.ndarray
    up: np.ndarray
    forward: np.ndarray
    side: np.ndarray
    crown: float
    front: float
    back: float
    half_width: float
    head_vertices: np.ndarray
    source: str = FRAME_FROM_BONE

    def local(self, points: np.ndarray) -> np.ndarray:
        """(n, 3) local coordinates ``(a, f, s)`` of points (n, 3)."""
        rel = np.asarray(points, dtype=np.float64) - self.origin
        return np.stack([rel @ self.up, rel @ self.forward, rel @ self.side], axis=-1)

    def normalised(self, points: np.ndarray) -> np.ndarray:
        """(n, 3) ``(eta, g, sigma)``: height / crown, forward in [-1, 1] from back to front,
        sideways / half-width (positive on the character's left)."""
        a, f, s = self.local(points).T
        mid = 0.5 * (self.front + self.back)
        half_depth = 0.5 * (self.front - self.back)
        return np.stack([a / self.crown, (f - mid) / half_depth, s / self.half_width], axis=-1)

    def world(self, a: float | np.ndarray, f: float | np.ndarray, s: float | np.ndarray = 0.0) -> np.ndarray:
        """World points from local coordinates (broadcast)."""
        a, f, s = np.broadcast_arrays(np.asarray(a, float), np.asarray(f, float), np.asarray(s, float))
        return self.origin + a[..., None] * self.up + f[..., None] * self.forward + s[..., None] * self.side

    @property
    def brow_height(self) -> float:
        """Height ``a`` (m) of the brows."""
        return BROW_HEIGHT * self.crown

    @property
    def centre(self) -> np.ndarray:
        """(3,) a point in the middle of the skull (m)."""
        return self.world(SKULL_REFERENCE_HEIGHT * self.crown, 0.5 * (self.front + self.back))


def head_frame(character: Character) -> HeadFrame:
    """The head frame of a character: from its ``head`` bone when it has a skeleton, else from
    its mesh (:func:`mesh_head_frame`).

    Parameters
    ----------
    character : Character
        With a skeleton, it needs a ``head`` bone; skin weights are used when present (without
        them every vertex above the head joint counts as head). Only the connected piece of
        the mesh (edge graph) holding most head vertices counts: separate eyes, teeth or
        lashes do not.

    Returns
    -------
    frame : HeadFrame

    Raises
    ------
    InputError
        ``bad_skeleton`` for a skeleton without a ``head`` bone or head vertices; ``not_a_head``
        for a rigless mesh the estimate cannot read.
    """
    if character.skeleton is None:
        return mesh_head_frame(character)
    try:
        head = character.skeleton.index("head")
    except KeyError:
        raise InputError("the skeleton has no bone named 'head'", character.name, "bad_skeleton") from None
    origin = character.skeleton.heads[head]
    axis = character.skeleton.tails[head] - origin
    if np.linalg.norm(axis) <= 0:
        raise InputError("the 'head' bone has zero length", character.name, "bad_skeleton")
    up = axis / np.linalg.norm(axis)
    forward = np.array([0.0, 0.0, 1.0]) - up[2] * up
    if np.linalg.norm(forward) < 0.1:
        raise InputError("the 'head' bone points along Z; expected Y up, face +Z", character.name, "bad_skeleton")
    forward /= np.linalg.norm(forward)
    side = np.cross(up, forward)
    rel = character.vertices - origin
    a = rel @ up
    if character.weights is not None:
        w = character.weights
        total = np.asarray(w.sum(axis=1)).ravel()
        head_w = np.asarray(w[:, head].todense()).ravel()
        is_head = head_w >= HEAD_WEIGHT_MIN * np.where(total > 0, total, np.inf)
    else:
        is_head = a > 0
    if not is_head.any():
        raise InputError("no vertex is dominated by the 'head' bone", character.name, "bad_skeleton")
    # the head is the connected piece of the mesh holding most head vertices: eyes, teeth,
    # lashes or a hat carried in the same mesh as separate pieces do not shape the frame
    piece = vertex_components(character.faces, character.n_vertices)
    is_head &= piece == np.argmax(np.bincount(piece[is_head]))
    crown = float(a[is_head].max())
    if crown <= 0:
        raise InputError("the head vertices lie below the head joint", character.name, "bad_skeleton")
    upper = is_head & (a > SKULL_REFERENCE_HEIGHT * crown)
    if not upper.any():
        upper = is_head
    f = rel[upper] @ forward
    s = rel[upper] @ side
    return HeadFrame(origin, up, forward, side, crown, float(f.max()), float(f.min()), float(np.abs(s).max()), is_head)


def mesh_head_frame(character: Character) -> HeadFrame:
    """The head frame of a character without a rig, from its mesh in hairport's axes (Y up, face +Z).

    The head is the topmost part of the connected piece of the mesh with the most vertices
    (separate eyes, teeth, lashes or a hat do not count). The crown height above the head
    joint and the skull's depth (front to back, above :data:`SKULL_REFERENCE_HEIGHT` of the
    crown) fix each other: starting from :data:`REFERENCE_CROWN_M`, the crown height becomes
    :data:`CROWN_PER_SKULL_DEPTH` depths, for :data:`MESH_FRAME_ROUNDS` rounds. The joint sits
    midway across the skull, :data:`JOINT_FORWARD_SHARE` of its depth in front of its back.
    On the MakeHuman presets with their rigs removed the joint lands 0.25-1.8 cm from the rig's
    and the crown height within 11 % (``tests/solver/body/test_head_frame.py`` holds them to
    2 cm and 12 %).

    Parameters
    ----------
    character : Character
        Canonical axes; a full body or a head alone (cut open at the neck, or closed).

    Returns
    -------
    frame : HeadFrame
        ``source`` :data:`FRAME_FROM_MESH`; ``head_vertices`` are those of the piece above
        :data:`HEAD_BELOW_JOINT_SHARE` crown heights below the joint.

    Raises
    ------
    InputError
        ``not_a_head`` when the top of the mesh has no depth (a flat mesh).
    """
    vertices = character.vertices
    piece = vertex_components(character.faces, character.n_vertices)
    used = np.zeros(character.n_vertices, dtype=bool)
    used[character.faces.ravel()] = True  # a Character has faces: it refuses a mesh without any
    main = used & (piece == np.argmax(np.bincount(piece[used])))
    up = np.array([0.0, 1.0, 0.0])
    forward = np.array([0.0, 0.0, 1.0])
    side = np.cross(up, forward)
    top = float(vertices[main, 1].max())

    def skull_below(crown: float) -> np.ndarray:
        """(K, 3) the piece's vertices above SKULL_REFERENCE_HEIGHT of ``crown`` over the joint."""
        skull = vertices[main & (vertices[:, 1] >= top - (1.0 - SKULL_REFERENCE_HEIGHT) * crown)]
        if not np.ptp(skull[:, 2]) > 0:
            raise InputError("the top of the mesh has no depth from the face to the back of the head: "
                             "is it a head, Y up and facing +Z?", character.name, "not_a_head")
        return skull

    crown = REFERENCE_CROWN_M
    for _ in range(MESH_FRAME_ROUNDS):
        crown = CROWN_PER_SKULL_DEPTH * float(np.ptp(skull_below(crown)[:, 2]))
    skull = skull_below(crown)
    back, depth = float(skull[:, 2].min()), float(np.ptp(skull[:, 2]))
    origin = np.array([0.5 * (skull[:, 0].min() + skull[:, 0].max()), top - crown, back + JOINT_FORWARD_SHARE * depth])
    rel = skull - origin
    half_width = float(np.abs(rel @ side).max())
    if not half_width > 0:
        raise InputError("the top of the mesh has no width", character.name, "not_a_head")
    f = rel @ forward
    return HeadFrame(origin, up, forward, side, crown, float(f.max()), float(f.min()), half_width,
                     main & ((vertices - origin) @ up > -HEAD_BELOW_JOINT_SHARE * crown), FRAME_FROM_MESH)
