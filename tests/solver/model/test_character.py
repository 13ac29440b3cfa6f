"""Characters and skeletons: checks on construction, bone lookup, the same-topology test."""

import numpy as np
import pytest
import scipy.sparse as sp

from hairport.solver.model.character import Character, Skeleton, check_same_topology, normalise_weight_rows
from hairport.solver.model.errors import InputError, TopologyMismatch

VERTICES = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
FACES = np.array([[0, 1, 2], [0, 3, 1], [0, 2, 3], [1, 3, 2]])


def skeleton() -> Skeleton:
    return Skeleton(("root", "head"), np.array([-1, 0]), np.zeros((2, 3)), np.array([[0, 1, 0], [0, 2, 0.0]]))


def test_bones_and_scaling():
    bones = skeleton()
    assert bones.n_bones == 2 and bones.index("head") == 1
    with pytest.raises(KeyError, match="no bone named 'neck'"):
        bones.index("neck")
    np.testing.assert_array_equal(bones.scaled(0.01).tails[1], [0, 0.02, 0])


@pytest.mark.parametrize("names, parents, code", [
    (("a", "a"), [-1, 0], "bad_skeleton"),
    (("a", "b"), [-1, 5], "bad_skeleton"),
    (("a",), [-1, 0], "bad_skeleton"),
])
def test_bad_skeletons(names, parents, code):
    with pytest.raises(InputError) as refused:
        Skeleton(names, np.array(parents), np.zeros((2, 3)), np.ones((2, 3)))
    assert refused.value.code == code


def test_bad_meshes_and_weights():
    with pytest.raises(InputError) as refused:
        Character(VERTICES, FACES + 1, name="body.obj")
    assert refused.value.code == "bad_mesh" and str(refused.value).startswith("body.obj: ")
    with pytest.raises(InputError) as refused:
        Character(np.where(VERTICES == 1, np.nan, VERTICES), FACES)
    assert refused.value.code == "non_finite"
    with pytest.raises(InputError) as refused:
        Character(VERTICES, FACES, weights=sp.csr_matrix(np.ones((4, 2))))
    assert refused.value.code == "bad_skeleton"
    rigged = Character(VERTICES, FACES, skeleton(), sp.csr_matrix(np.ones((4, 2))), "rigged")
    moved = rigged.with_vertices(VERTICES * 2)
    assert moved.skeleton is rigged.skeleton and moved.n_vertices == 4 and moved.n_faces == 4


def test_same_topology():
    body = Character(VERTICES, FACES, name="a")
    check_same_topology(body, Character(VERTICES * 3, FACES, name="b"))
    with pytest.raises(TopologyMismatch, match="topology") as refused:
        check_same_topology(body, Character(VERTICES, FACES[:, ::-1], name="b"))
    assert refused.value.code == "topology_mismatch" and refused.value.source == "b"
    with pytest.raises(TopologyMismatch):
        check_same_topology(body, Character(np.vstack([VERTICES, [[2, 2, 2]]]), FACES, name="c"))


def test_normalise_weight_rows():
    # duplicates are summed, an explicit zero and an all-zero row stay out
    weights = sp.csr_matrix(([1.0, 2.0, 0.0, 2.0, 2.0, 1.0], ([0, 0, 1, 2, 2, 0], [0, 1, 1, 0, 1, 1])), shape=(3, 2))
    normalised = normalise_weight_rows(weights)
    np.testing.assert_array_equal(normalised.toarray(), [[0.25, 0.75], [0.0, 0.0], [0.5, 0.5]])
    assert normalised.nnz == 4 and normalised.dtype == np.float64
