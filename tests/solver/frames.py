"""Characters and grooms written in other frames (units, axes) than hairport's, for the frame tests."""

from __future__ import annotations

import numpy as np

from hairport.solver.model.character import Character, Skeleton
from hairport.solver.model.frame import InputFrame
from hairport.solver.model.hair import Hair


def character_in(frame: InputFrame, character: Character, rigged: bool = True) -> Character:
    """A canonical character as a file in ``frame`` would hold it (its axes, its units)."""
    scale = frame.scale
    skeleton = character.skeleton
    if skeleton is not None and rigged:
        skeleton = Skeleton(skeleton.names, skeleton.parents, frame.axes_out(skeleton.heads) / scale,
                            frame.axes_out(skeleton.tails) / scale)
    else:
        skeleton = None
    weights = character.weights if skeleton is not None else None
    return Character(frame.axes_out(character.vertices) / scale, character.faces, skeleton, weights, character.name)


def hair_in(frame: InputFrame, hair: Hair) -> Hair:
    """A canonical groom as a file in ``frame`` would hold it."""
    thickness = None if hair.thickness is None else hair.thickness / frame.scale
    return Hair(frame.axes_out(hair.points) / frame.scale, hair.offsets, thickness, hair.color)


def head_faces(character: Character, below_head_joint: float = 0.04) -> np.ndarray:
    """(F,) bool: the faces of a rigged character above its head joint less ``below_head_joint`` (m)."""
    joint = character.skeleton.heads[character.skeleton.index("head")]
    return character.vertices[character.faces][:, :, 1].min(axis=1) > joint[1] - below_head_joint


def faces_only(character: Character, keep: np.ndarray, name: str) -> Character:
    """The mesh of ``keep`` (F,) bool faces with their vertices only, no rig: the same ``keep``
    cuts characters of one topology into characters of one (smaller) topology."""
    used = np.unique(character.faces[keep])
    index = np.full(character.n_vertices, -1)
    index[used] = np.arange(len(used))
    return Character(character.vertices[used], index[character.faces[keep]], name=name)


def head_only(character: Character, below_head_joint: float = 0.04) -> Character:
    """A rigged character's head cut at the neck (:func:`head_faces`), open at the cut, without a rig."""
    return faces_only(character, head_faces(character, below_head_joint), f"{character.name}-head")
