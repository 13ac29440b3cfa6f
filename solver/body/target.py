"""A target character made ready for a hairstyle: same topology; the source's skeleton, in its order, if it has one."""

from __future__ import annotations

from typing import Protocol

import numpy as np

from hairport.solver.body.skeleton_transfer import ensure_skeleton
from hairport.solver.model.character import Character, Skeleton, check_same_topology
from hairport.solver.model.errors import InputError


class RiggedSource(Protocol):
    """What a target is prepared for: the source character and the bone order its hair uses
    (an :class:`~hairport.solver.adaptable.AdaptableHairstyle`)."""

    source: Character
    bone_names: tuple[str, ...]


def prepare_target(adaptable: RiggedSource, target: Character) -> Character:
    """Check topology, give the target a skeleton if it has none, and put its bones in the source's order.

    Parameters
    ----------
    adaptable : RiggedSource
        The source character and its bone names, in the order of the hairstyle's weights.
    target : Character

    Returns
    -------
    target : Character
        ``target`` itself when its bones are already those of the source, in that order, or
        when the source has no skeleton (its hairstyle is anchored by the surface);
        else the same mesh with the source's skeleton transferred (no skeleton) or with
        its bones, parents and skin-weight columns permuted into ``adaptable.bone_names``.

    Raises
    ------
    TopologyMismatch
    InputError
        ``bad_skeleton`` when the target lacks a bone of the source; ``no_skeleton`` when
        neither character has a skeleton.
    """
    check_same_topology(adaptable.source, target)
    if adaptable.source.skeleton is None:
        return target  # anchored by the surface: the target's skeleton, if any, plays no part
    target = ensure_skeleton(adaptable.source, target)
    if target.skeleton.names != adaptable.bone_names:
        missing = sorted(set(adaptable.bone_names) - set(target.skeleton.names))
        if missing:
            raise InputError(f"target skeleton lacks bones {missing[:5]}", target.name, "bad_skeleton")
        order = [target.skeleton.names.index(name) for name in adaptable.bone_names]
        parents = np.array([
            adaptable.bone_names.index(target.skeleton.names[p]) if p >= 0 else -1 for p in target.skeleton.parents[order]
        ])
        skeleton = Skeleton(adaptable.bone_names, parents, target.skeleton.heads[order], target.skeleton.tails[order])
        weights = target.weights[:, order] if target.weights is not None else None
        target = Character(target.vertices, target.faces, skeleton, weights, target.name)
    return target
