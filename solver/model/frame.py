"""The frame of an input: its length unit and which of its axes point up and to the front.

hairport solves in one canonical frame: meters, +Y up, the face looking along +Z, +X the
character's left (MakeHuman's and glTF's convention). Inputs in another frame are brought
into it on load and outputs are written back in the frame of the input they came from
(:class:`InputFrame`), so every stage in between (head frame, hairline split, presets,
previews) works in one convention.

Axes are named ``+x -x +y -y +z -z`` (``x`` means ``+x``). ``up`` and ``front`` are input
axes; the third canonical axis (the character's left) is ``up x front``, so the map from
input to canonical coordinates is a proper rotation (a signed permutation of the
coordinates, exact in floating point) and keeps the orientation of triangles: a mirrored
input stays a mirrored character, with its faces still counter-clockwise seen from outside.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from hairport.solver.model.character import Character, Skeleton
from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import Hair
from hairport.solver.model.units import unit_scale

#: the axis names, in the order of :data:`AXIS_VECTORS`
AXES: tuple[str, ...] = ("+x", "-x", "+y", "-y", "+z", "-z")
#: what the command line and the API accept for an axis (a missing sign means +)
AXIS_CHOICES: tuple[str, ...] = ("x", "y", "z", *AXES)
#: the value of an option (units, axes, anchoring) that asks hairport to infer it from the inputs
AUTO = "auto"
#: the unit vector of each axis name
AXIS_VECTORS: dict[str, np.ndarray] = {
    name: np.eye(3)[i // 2] * (1.0 if name[0] == "+" else -1.0) for i, name in enumerate(AXES)
}
#: hairport's own frame: up and front axes
CANONICAL_UP, CANONICAL_FRONT = "+y", "+z"


def parse_axis(name: str, what: str = "axis") -> str:
    """The normalised name (``+x`` ... ``-z``) of an axis written ``x``, ``+x``, ``-X``, ...

    Raises
    ------
    InputError
        Code ``bad_axis``.
    """
    text = str(name).strip().lower()
    if text in ("x", "y", "z"):
        text = "+" + text
    if text not in AXIS_VECTORS:
        raise InputError(f"unknown {what} {name!r}; expected one of {', '.join(AXIS_CHOICES)}", code="bad_axis")
    return text


def axis_name(vector: np.ndarray) -> str:
    """The name of the signed coordinate axis nearest a (3,) direction."""
    vector = np.asarray(vector, dtype=np.float64)
    i = int(np.argmax(np.abs(vector)))
    return ("+" if vector[i] >= 0 else "-") + "xyz"[i]


@dataclass(frozen=True)
class InputFrame:
    """How the coordinates of an input map to hairport's canonical frame.

    Attributes
    ----------
    units : str
        Length unit of the input file (one of ``m``, ``dm``, ``cm``, ``mm``).
    up : str
        The input axis that points up (``+y`` in the canonical frame).
    front : str
        The input axis the face looks along (``+z`` in the canonical frame); perpendicular
        to ``up``.
    """

    units: str = "m"
    up: str = CANONICAL_UP
    front: str = CANONICAL_FRONT

    def __post_init__(self) -> None:
        unit_scale(self.units)
        up, front = parse_axis(self.up, "up axis"), parse_axis(self.front, "front axis")
        if up[1] == front[1]:
            raise InputError(f"the up axis {up} and the front axis {front} must be perpendicular", code="bad_axis")
        object.__setattr__(self, "up", up)
        object.__setattr__(self, "front", front)

    @property
    def scale(self) -> float:
        """Meters per input unit."""
        return unit_scale(self.units)

    @property
    def rotation(self) -> np.ndarray:
        """(3, 3) float64 ``R`` with ``canonical = R @ input``: rows left, up, front (in input axes)."""
        up, front = AXIS_VECTORS[self.up], AXIS_VECTORS[self.front]
        return np.stack([np.cross(up, front), up, front])

    @property
    def is_canonical_axes(self) -> bool:
        """Whether the input's axes are already hairport's (nothing to rotate)."""
        return (self.up, self.front) == (CANONICAL_UP, CANONICAL_FRONT)

    def axes_in(self, points: np.ndarray) -> np.ndarray:
        """(n, 3) input directions or positions with canonical axes (lengths unchanged).

        A signed permutation of the columns: exact, and undone exactly by :meth:`axes_out`.
        """
        columns, signs = _permutation(self.rotation)
        return np.asarray(points, dtype=np.float64)[..., columns] * signs

    def axes_out(self, points: np.ndarray) -> np.ndarray:
        """(n, 3) canonical positions with the input's axes (the inverse of :meth:`axes_in`)."""
        columns, signs = _permutation(self.rotation.T)
        return np.asarray(points, dtype=np.float64)[..., columns] * signs

    def describe(self) -> str:
        """``"mm, up +z, front -y"``."""
        return f"{self.units}, up {self.up}, front {self.front}"

    def to_dict(self) -> dict:
        return {"units": self.units, "up": self.up, "front": self.front}

    @classmethod
    def from_dict(cls, document: dict | None) -> "InputFrame":
        """The frame a :meth:`to_dict` record describes (the canonical frame for ``None``)."""
        if not document:
            return cls()
        return cls(document.get("units", "m"), document.get("up", CANONICAL_UP), document.get("front", CANONICAL_FRONT))


def _permutation(rotation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Columns and signs of a signed-permutation matrix: ``(R @ p)[i] = signs[i] * p[columns[i]]``."""
    columns = np.argmax(np.abs(rotation), axis=1)
    signs = rotation[np.arange(3), columns]
    return columns, signs


def character_axes_in(frame: InputFrame, character: Character, scale: float = 1.0) -> Character:
    """The character with canonical axes, its lengths multiplied by ``scale``.

    The faces are kept as they are (a rotation keeps their orientation), the skin weights too.
    """
    if frame.is_canonical_axes and scale == 1.0:
        return character
    skeleton = character.skeleton
    if skeleton is not None:
        skeleton = Skeleton(skeleton.names, skeleton.parents, frame.axes_in(skeleton.heads) * scale,
                            frame.axes_in(skeleton.tails) * scale)
    return Character(frame.axes_in(character.vertices) * scale, character.faces, skeleton, character.weights,
                     character.name)


def hair_axes_in(frame: InputFrame, hair: Hair, scale: float = 1.0) -> Hair:
    """The hairstyle with canonical axes, its lengths (points, thickness) multiplied by ``scale``."""
    if frame.is_canonical_axes and scale == 1.0:
        return hair
    thickness = None if hair.thickness is None else hair.thickness * scale
    return replace(hair, points=frame.axes_in(hair.points) * scale, thickness=thickness)


def hair_axes_out(frame: InputFrame, hair: Hair) -> Hair:
    """The hairstyle with the input's axes (still in meters: the writer converts the units)."""
    if frame.is_canonical_axes:
        return hair
    return replace(hair, points=frame.axes_out(hair.points))
