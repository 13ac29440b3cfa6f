"""Bones from the joints of a skin: their tails and their names, as the glTF and USD readers make them.

A file's skin gives every joint a bind-pose position (the bone's head) and a parent joint, but
no tail. Bone ``b``'s tail is the mean head of its child joints; a leaf (or a bone whose children
meet at its head) extends from its head along the direction from its parent's head by
:data:`LEAF_TAIL_FRACTION` of that distance; a joint with neither parent nor children points along
its local +Y axis with a length of :data:`ISOLATED_BONE_FRACTION` of the mesh's bounding-box
diagonal. Joint names that repeat are made unique by a ``_<b>`` suffix.
"""

from __future__ import annotations

import numpy as np

#: leaf bone: tail = head + LEAF_TAIL_FRACTION * (head - parent head)
LEAF_TAIL_FRACTION = 0.5
#: bone with neither parent nor child joints: length as a fraction of the mesh's
#: bounding-box diagonal, along the joint's local +Y axis (the glTF/Blender bone axis)
ISOLATED_BONE_FRACTION = 0.05
#: a tail closer to its head than this fraction of the bounding-box diagonal counts as none
MIN_BONE_LENGTH_FRACTION = 1e-6


def bone_tails(heads: np.ndarray, parents: np.ndarray, bind: np.ndarray, diagonal: float) -> np.ndarray:
    """(B, 3) tails: the mean head of the children; leaves and isolated joints as in the module notes.

    Parameters
    ----------
    heads : (B, 3) float64
    parents : (B,) int64
    bind : (B, 4, 4) float64
        Bind-pose transforms (their +Y axis points an isolated joint's bone).
    diagonal : float
        The mesh's bounding-box diagonal.
    """
    n_bones = len(heads)
    has_parent = parents >= 0
    child_sum = np.zeros((n_bones, 3))
    np.add.at(child_sum, parents[has_parent], heads[has_parent])
    child_count = np.bincount(parents[has_parent], minlength=n_bones)
    tails = child_sum / np.maximum(child_count, 1)[:, None]
    leaf = (child_count == 0) | (np.linalg.norm(tails - heads, axis=1) < MIN_BONE_LENGTH_FRACTION * diagonal)
    from_parent = heads - heads[np.maximum(parents, 0)]
    extend = leaf & has_parent & (np.linalg.norm(from_parent, axis=1) >= MIN_BONE_LENGTH_FRACTION * diagonal)
    tails[extend] = heads[extend] + LEAF_TAIL_FRACTION * from_parent[extend]
    isolated = leaf & ~extend
    if isolated.any():
        axis_y = bind[isolated, :3, 1]
        axis_y = axis_y / np.maximum(np.linalg.norm(axis_y, axis=1, keepdims=True), np.finfo(float).tiny)
        axis_y[np.linalg.norm(axis_y, axis=1) == 0] = [0.0, 1.0, 0.0]
        tails[isolated] = heads[isolated] + ISOLATED_BONE_FRACTION * diagonal * axis_y
    return tails


def unique_names(raw_names: list[str]) -> list[str]:
    """Names that repeat get the suffix ``_<index>``; the others stay."""
    seen: dict[str, int] = {}
    for name in raw_names:
        seen[name] = seen.get(name, 0) + 1
    return [f"{name}_{b}" if seen[name] > 1 else name for b, name in enumerate(raw_names)]
