"""The adaptive weights of Eq. 20."""

import numpy as np
import pytest

from hairport.solver.hairline.weights import GAMMA_SIGMA, adaptive_weights
from hairport.solver.model.hair import Hair


def straight_strands():
    """Two strands of 4 particles, 1 cm apart along z."""
    strand = np.array([[0, 0, 0], [0, 0, 0.01], [0, 0, 0.02], [0, 0, 0.03]], dtype=float)
    return Hair.from_strands([strand, strand + [0.1, 0, 0]])


def test_weights_are_zero_at_a_moved_root_and_one_for_unmoved_strands():
    hair = straight_strands()
    gamma = adaptive_weights(hair, np.array([0.02, 0.0]))
    assert gamma[0] == 0.0
    np.testing.assert_array_equal(gamma[4:], 1.0)  # root did not move: r = 0 -> gamma = 1
    s = np.array([0.0, 0.01, 0.02, 0.03])
    np.testing.assert_allclose(gamma[:4], 1 - np.exp(-GAMMA_SIGMA * (s / 0.02) ** 2), rtol=0, atol=1e-15)
    assert np.all(np.diff(gamma[:4]) > 0)  # grows along the strand


def test_weights_tend_to_one_far_along_the_strand():
    long = Hair.from_strands([np.column_stack([np.zeros(50), np.zeros(50), np.linspace(0, 1.0, 50)])])
    gamma = adaptive_weights(long, np.array([0.01]))
    assert gamma[-1] > 1 - 1e-12 and gamma[0] == 0


def test_weights_refuse_a_wrong_shape():
    with pytest.raises(ValueError, match=r"expected \(2,\)"):
        adaptive_weights(straight_strands(), np.zeros(3))



def test_weights_follow_the_arc_length_of_each_strand():
    # a bent strand (3-4-5 segments: arc 0, 5, 10 cm) of 3 particles, then a straight one of 2
    bent = np.array([[0.0, 0.0, 0.0], [0.03, 0.04, 0.0], [0.03, 0.04, 0.05]])
    short = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.02]])
    hair = Hair.from_strands([bent, short])
    gamma = adaptive_weights(hair, np.array([0.05, 0.01]), sigma=0.5)
    expected = np.concatenate([1.0 - np.exp(-0.5 * (np.array([0.0, 0.05, 0.10]) / 0.05) ** 2),
                               1.0 - np.exp(-0.5 * (np.array([0.0, 0.02]) / 0.01) ** 2)])
    np.testing.assert_allclose(gamma, expected, rtol=1e-15, atol=0)
    np.testing.assert_array_equal(gamma[hair.roots], [0.0, 0.0])
    # a larger sigma relaxes less: every weight off the root grows
    stiffer = adaptive_weights(hair, np.array([0.05, 0.01]), sigma=2.0)
    assert np.all(stiffer[1:3] > gamma[1:3]) and np.all(stiffer[hair.roots] == 0.0)


def test_no_root_moved_keeps_every_weight_at_one():
    hair = straight_strands()
    np.testing.assert_array_equal(adaptive_weights(hair, np.zeros(2)), np.ones(8))
