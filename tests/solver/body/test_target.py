"""Tests for solver/body/target.py: a target made ready for a source's hairstyle."""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
import pytest
import scipy.sparse as sp

from hairport.solver.adaptable import AdaptableHairstyle
from hairport.solver.body.target import prepare_target
from hairport.solver.model.character import Character, Skeleton
from hairport.solver.model.errors import InputError, TopologyMismatch
from tests.solver.capsule import capsule_mesh, chain_skeleton

#: the capsule's joints are regressed from its own vertices to rounding (m)
REFLEXIVE_TOLERANCE_M = 1e-10


@dataclass(frozen=True)
class Source:
    """The part of an adaptable hairstyle that :func:`prepare_target` reads."""

    source: Character
    bone_names: tuple[str, ...]


@pytest.fixture(scope="module")
def source() -> Source:
    vertices, faces = capsule_mesh(30, 24)
    skeleton = chain_skeleton()
    # vertex v weighs bone b by 1 + (v + b) mod 3: every row differs, so a column swap shows
    v, b = np.meshgrid(np.arange(len(vertices)), np.arange(skeleton.n_bones), indexing="ij")
    weights = sp.csr_matrix((1.0 + (v + b) % 3) / (3.0 + 3.0))
    return Source(Character(vertices, faces, skeleton, weights, "source"), skeleton.names)


def test_the_protocol_is_what_an_adaptable_hairstyle_holds():
    names = {field.name for field in fields(AdaptableHairstyle)}
    assert {"source", "bone_names"} <= names


def test_a_target_in_the_source_order_is_kept(source):
    target = Character(source.source.vertices * 1.1, source.source.faces, source.source.skeleton,
                       source.source.weights, "target")
    assert prepare_target(source, target) is target


def test_bones_are_reordered_with_parents_and_weights(source):
    chain = source.source.skeleton
    order = [2, 0, 1]  # the target lists head, pelvis, spine
    shuffled = Skeleton([chain.names[b] for b in order], [2, -1, 1], chain.heads[order] + 1.0, chain.tails[order] + 1.0)
    weights = source.source.weights[:, order]
    target = Character(source.source.vertices + 1.0, source.source.faces, shuffled, weights, "target")
    prepared = prepare_target(source, target)
    assert prepared.skeleton.names == ("pelvis", "spine", "head") and prepared.name == "target"
    np.testing.assert_array_equal(prepared.skeleton.parents, [-1, 0, 1])
    np.testing.assert_array_equal(prepared.skeleton.heads, chain.heads + 1.0)
    np.testing.assert_array_equal(prepared.skeleton.tails, chain.tails + 1.0)
    np.testing.assert_array_equal(prepared.weights.toarray(), source.source.weights.toarray())
    np.testing.assert_array_equal(prepared.vertices, target.vertices)


def test_missing_bones_are_refused(source):
    chain = source.source.skeleton
    partial = Skeleton(chain.names[:2], chain.parents[:2], chain.heads[:2], chain.tails[:2])
    target = Character(source.source.vertices, source.source.faces, partial, name="target")
    with pytest.raises(InputError) as error:
        prepare_target(source, target)
    assert error.value.code == "bad_skeleton" and error.value.source == "target"
    assert "lacks bones ['head']" in error.value.problem


def test_a_target_without_skeleton_gets_the_transferred_one(source):
    target = Character(source.source.vertices * 2.0, source.source.faces, name="bare")
    prepared = prepare_target(source, target)
    assert prepared.skeleton.names == source.bone_names and prepared.name == "bare"
    # same topology: the source's weights apply
    np.testing.assert_array_equal(prepared.weights.toarray(), source.source.weights.toarray())
    # the joint regressor commutes with scaling: the joints double too
    np.testing.assert_allclose(prepared.skeleton.heads, 2.0 * source.source.skeleton.heads,
                               atol=REFLEXIVE_TOLERANCE_M, rtol=0)
    np.testing.assert_allclose(prepared.skeleton.tails, 2.0 * source.source.skeleton.tails,
                               atol=REFLEXIVE_TOLERANCE_M, rtol=0)


def test_topology_mismatch_is_refused(source):
    flipped = Character(source.source.vertices, source.source.faces[:, ::-1], source.source.skeleton, name="flipped")
    with pytest.raises(TopologyMismatch) as error:
        prepare_target(source, flipped)
    assert error.value.code == "topology_mismatch" and "face 0 differs" in error.value.problem
    fewer = Character(source.source.vertices[:-1], source.source.faces[:-24], name="fewer")
    with pytest.raises(TopologyMismatch, match="the source has 722 vertices, the target has 721"):
        prepare_target(source, fewer)
