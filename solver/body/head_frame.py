"""A head-aligned frame from the head bone and the mesh: where up, forward and the skull are."""

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
    """The head frame of a rigged character.

    Parameters
    ----------
    character : Character
        Needs a skeleton with a ``head`` bone; skin weights are used when present (without
        them every vertex above the head joint counts as head). Only the connected piece of
        the mesh (edge graph) holding most head vertices counts: separate eyes, teeth or
        lashes do not.

    Returns
    -------
    frame : HeadFrame

    Raises
    ------
    InputError
        ``no_skeleton`` without a skeleton; ``bad_skeleton`` without a ``head`` bone or head vertices.
    """
    if character.skeleton is None:
        raise InputError(
            "the character has no skeleton: hairline edits and presets take the head's frame from a 'head' bone "
            "(give a skeleton JSON or a glTF skin, or retarget without a hairline edit)",
            character.name, "no_skeleton",
        )
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
