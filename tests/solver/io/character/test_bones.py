"""Bones from a skin's joints (solver/io/character/bones.py): tails from children, leaves and isolated
joints, and names made unique, with exact numbers."""

import numpy as np

from hairport.solver.io.character.bones import ISOLATED_BONE_FRACTION, LEAF_TAIL_FRACTION, bone_tails, unique_names

IDENTITY = np.eye(4)


def test_a_tail_is_the_mean_head_of_the_children_and_a_leaf_continues_from_its_parent():
    heads = np.array([[0.0, 0, 0], [1, 1, 0], [-1, 1, 0], [-1, 3, 0]])
    tails = bone_tails(heads, np.array([-1, 0, 0, 2]), np.stack([IDENTITY] * 4), diagonal=10.0)
    np.testing.assert_allclose(tails, [[0, 1, 0],  # between its two children
                                       [1 + LEAF_TAIL_FRACTION, 1 + LEAF_TAIL_FRACTION, 0],  # a leaf
                                       [-1, 3, 0],  # its one child
                                       [-1, 3 + 2 * LEAF_TAIL_FRACTION, 0]], atol=1e-15)


def test_an_isolated_joint_points_along_its_own_y_axis():
    quarter_turn_x = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])  # local +y -> +z
    tails = bone_tails(np.array([[5.0, 0, 0]]), np.array([-1]), quarter_turn_x[None], diagonal=2.0)
    np.testing.assert_allclose(tails, [[5, 0, ISOLATED_BONE_FRACTION * 2.0]], atol=1e-15)
    # a bind transform without a y axis: +y
    tails = bone_tails(np.array([[5.0, 0, 0]]), np.array([-1]), np.zeros((1, 4, 4)), diagonal=2.0)
    np.testing.assert_allclose(tails, [[5, ISOLATED_BONE_FRACTION * 2.0, 0]], atol=1e-15)


def test_children_at_the_head_make_a_leaf_and_a_parent_at_the_head_an_isolated_joint():
    heads = np.array([[0.0, 0, 0], [0, 1, 0], [0, 1, 0]])
    tails = bone_tails(heads, np.array([-1, 0, 1]), np.stack([IDENTITY] * 3), diagonal=10.0)
    np.testing.assert_allclose(tails, [[0, 1, 0],
                                       [0, 1 + LEAF_TAIL_FRACTION, 0],  # its child sits at its head
                                       [0, 1 + ISOLATED_BONE_FRACTION * 10.0, 0]], atol=1e-15)


def test_repeated_names_get_their_index():
    assert unique_names(["a", "b", "a"]) == ["a_0", "b", "a_2"]
    assert unique_names(["root", "spine"]) == ["root", "spine"]
    assert unique_names([]) == []
