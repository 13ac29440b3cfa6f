"""Landmarks a user gives to help a wrap: the same named points on the source body and on the target.

A landmarks document names a few points on each mesh (the crown, the tip of the nose, the chin,
the tops of the ears, the nape), each in that mesh's own file coordinates (its units and axes,
as a modelling tool shows them):

    {"source": {"nose_tip": [0.0, 1.62, 0.11], "chin": [...], ...},
     "target": {"nose_tip": [0.3, 171.0, 12.4], "chin": [...], ...}}

Both sides name the same points. :meth:`LandmarkPairs.in_canonical` brings them into
hairport's frame with the frames the inputs were read in; the wrap then pulls each source
point onto its target point in its stiff first steps (:mod:`hairport.solver.wrap.landmarks`).
"""

from __future__ import annotations

import hashlib
import math
import os
from dataclasses import dataclass

import numpy as np

from hairport.solver.model.errors import InputError
from hairport.solver.model.frame import InputFrame
from hairport.solver.model.json_input import parse_json
from hairport.solver.model.units import METERS_PER_UNIT

#: the code of every refusal of a landmarks document
BAD_LANDMARKS = "bad_landmarks"
#: the most landmarks a document may name: a wrap needs a handful; more add nothing but work
MAX_LANDMARKS = 32
#: the longest landmark name (characters)
MAX_LANDMARK_NAME_CHARS = 64
#: the largest landmarks file (bytes): 32 named points take about 2 KB
MAX_LANDMARKS_FILE_BYTES = 64 * 1024
#: the two sides of a document
SIDES = ("source", "target")


@dataclass(frozen=True, eq=False)
class LandmarkPairs:
    """Named points on the source and on the target that a wrap brings together.

    Attributes
    ----------
    names : tuple of str
        Sorted.
    source : (k, 3) float64
        On the source body, in the order of ``names``.
    target : (k, 3) float64
        On the target, in the same order.
    """

    names: tuple[str, ...]
    source: np.ndarray
    target: np.ndarray

    @classmethod
    def from_document(cls, document: object, where: str = "landmarks") -> "LandmarkPairs":
        """The pairs of a landmarks document (module docstring).

        Raises
        ------
        InputError
            ``bad_landmarks`` naming what is wrong: not an object with ``source`` and ``target``,
            names on one side only, no names or more than :data:`MAX_LANDMARKS`, a point that is not
            three finite numbers.
        """
        if not isinstance(document, dict) or set(document) != set(SIDES):
            raise InputError('expected an object with exactly the keys "source" and "target", each naming points '
                             '{"name": [x, y, z]}', where, BAD_LANDMARKS)
        sides = {side: _side_points(document[side], f"{where}.{side}") for side in SIDES}
        only = {side: sorted(set(sides[side]) - set(sides[other])) for side, other in (SIDES, SIDES[::-1])}
        for side in SIDES:
            if only[side]:
                raise InputError(f"{', '.join(map(repr, only[side]))} named on the {side} only; both sides name the "
                                 "same points", where, BAD_LANDMARKS)
        names = tuple(sorted(sides["source"]))
        return cls(names, *(np.array([sides[side][name] for name in names], dtype=np.float64) for side in SIDES))

    def to_document(self) -> dict:
        """The document :meth:`from_document` reads (JSON-ready)."""
        return {side: {name: [float(v) for v in point] for name, point in zip(self.names, points)}
                for side, points in zip(SIDES, (self.source, self.target))}

    def in_canonical(self, source_frame: InputFrame, source_units: str, target_frame: InputFrame) -> "LandmarkPairs":
        """The points in hairport's frame (meters, Y up, the face toward +Z), from each file's own coordinates.

        Parameters
        ----------
        source_frame : InputFrame
            The groom's frame (its axes are the source body's).
        source_units : str
            The source body file's units.
        target_frame : InputFrame
            The target file's units and axes (as :func:`~hairport.solver.inputs.canonical_target` found them).
        """
        source = source_frame.axes_in(self.source) * METERS_PER_UNIT[source_units]
        target = target_frame.axes_in(self.target) * target_frame.scale
        return LandmarkPairs(self.names, source, target)

    def pairs(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """``{name: (source point, target point)}``, as :func:`hairport.solver.wrap.wrap_body` takes them."""
        return {name: (s, t) for name, s, t in zip(self.names, self.source, self.target)}

    def digest(self) -> str:
        """A content digest (16 hex characters) of the names and points, for cache keys."""
        content = "|".join(self.names).encode() + self.source.tobytes() + self.target.tobytes()
        return hashlib.blake2b(content, digest_size=8).hexdigest()

    def describe(self) -> str:
        return f"{len(self.names)} landmarks ({', '.join(self.names)})"


def _side_points(side: object, where: str) -> dict[str, list[float]]:
    """One side's ``{name: [x, y, z]}``, checked."""
    if not isinstance(side, dict) or not side:
        raise InputError('expected an object naming at least one point {"name": [x, y, z]}', where, BAD_LANDMARKS)
    if len(side) > MAX_LANDMARKS:
        raise InputError(f"{len(side)} landmarks, more than the limit of {MAX_LANDMARKS}", where, BAD_LANDMARKS)
    for name, point in side.items():
        if not name or len(name) > MAX_LANDMARK_NAME_CHARS:
            raise InputError(f"landmark names have 1 to {MAX_LANDMARK_NAME_CHARS} characters, not {len(name)}", where,
                             BAD_LANDMARKS)
        if (not isinstance(point, list) or len(point) != 3
                or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in point)):
            raise InputError(f"landmark {name!r} is not three finite numbers [x, y, z]", where, BAD_LANDMARKS)
    return side


def read_landmarks(path: str | os.PathLike) -> LandmarkPairs:
    """The landmark pairs of a JSON file (module docstring).

    Raises
    ------
    InputError
        ``too_large`` above :data:`MAX_LANDMARKS_FILE_BYTES`, ``bad_json`` for a file that is not JSON,
        ``bad_landmarks`` (:meth:`LandmarkPairs.from_document`).
    """
    source = os.fspath(path)
    size = os.path.getsize(source)
    if size > MAX_LANDMARKS_FILE_BYTES:
        raise InputError(f"file has {size} bytes, more than the limit of {MAX_LANDMARKS_FILE_BYTES}", source,
                         "too_large")
    with open(source, "rb") as handle:
        document = parse_json(handle.read(), source, "bad_json")
    return LandmarkPairs.from_document(document, source)
