"""A target character made ready for a hairstyle: same topology, a skeleton, bones in the source's order."""

from __future__ import annotations

import numpy as np

from hairport.solver.adaptable import AdaptableHairstyle
from hairport.solver.body.skeleton_transfer import ensure_skeleton
from hairport.solver.model.character import Character, Skeleton, check_same_topology
from hairport.solver.model.errors import InputError


def prepare_target(adaptable: AdaptableHairstyle, target: Character) -> Character:
    """Check topology, give the target a skeleton if it has none, and check its bones."""
    check_same_topology(adaptable.source, target)
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
