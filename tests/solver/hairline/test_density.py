"""Table 3's density change against hand values."""

import numpy as np
import pytest

from hairport.solver.hairline.density import density_change
from tests.solver.hairline.unit_square import bowl, expect_refusal, flat, square_grid


def test_density_change_of_a_uniform_scaling():
    uv, triangles = square_grid()
    rest = bowl(uv)
    roots = np.array([0, 0, 5, -1, 17, 17, 17, 100, -1])
    for s in (0.8, 1.0, 1.25):
        density = density_change(rest, s * rest, triangles, roots)
        np.testing.assert_array_equal(density.triangles, [0, 5, 17, 100])
        np.testing.assert_allclose(density.changes, np.full(4, 1.0 / s**2 - 1.0), rtol=0, atol=1e-12)
        assert density.l1 == pytest.approx(abs(1.0 / s**2 - 1.0), abs=1e-12)
        assert density.linf == pytest.approx(abs(1.0 / s**2 - 1.0), abs=1e-12)
    identity = density_change(rest, rest, triangles, roots)
    assert identity.l1 == identity.linf == 0.0
    np.testing.assert_array_equal(identity.changes, np.zeros(4))


def test_density_change_by_hand():
    rest = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 0.0]])
    triangles = np.array([[0, 1, 2], [1, 3, 2]])
    # one triangle: its area doubles (0.5 -> 1), the density halves
    stretched = rest.copy()
    stretched[1, 0] = 2.0
    density = density_change(rest, stretched, triangles[:1], np.array([0, 0, 0]))
    np.testing.assert_allclose(density.changes, [-0.5], rtol=0, atol=1e-15)
    assert (density.l1, density.linf) == pytest.approx((0.5, 0.5), abs=1e-15)
    # lifted out of the plane: area 0.5 sqrt(2), change 1 / sqrt(2) - 1
    lifted = rest.copy()
    lifted[2, 2] = 1.0
    density = density_change(rest, lifted, triangles[:1], np.array([0]))
    np.testing.assert_allclose(density.changes, [1.0 / np.sqrt(2.0) - 1.0], rtol=0, atol=1e-15)
    # two triangles: the first stretched to twice its area (-0.5), the second compressed to
    # half (+1); roots outside the scalp (-1) are ignored
    deformed = rest.copy()
    deformed[0] = [-0.5, -0.5, 0.0]  # first triangle (0, 1, 2): area 0.5 -> 1.0
    deformed[3] = [0.75, 0.75, 0.0]  # second triangle (1, 3, 2): area 0.5 -> 0.25
    density = density_change(rest, deformed, triangles, np.array([1, -1, 0, 1]))
    np.testing.assert_array_equal(density.triangles, [0, 1])
    np.testing.assert_allclose(density.changes, [-0.5, 1.0], rtol=0, atol=1e-15)
    assert density.l1 == pytest.approx(0.75, abs=1e-15)
    assert density.linf == pytest.approx(1.0, abs=1e-15)
    # a collapsed triangle holding roots: infinite change
    collapsed = rest.copy()
    collapsed[2] = [0.5, 0.0, 0.0]
    density = density_change(rest, collapsed, triangles, np.array([0, 1]))
    assert np.isinf(density.changes[0]) and density.linf == np.inf


def test_density_change_without_roots():
    uv, triangles = square_grid(2)
    for roots in (np.zeros(0, dtype=np.int64), np.array([-1, -1]), []):
        density = density_change(flat(uv), 2.0 * flat(uv), triangles, roots)
        assert density.l1 == density.linf == 0.0
        assert density.changes.shape == density.triangles.shape == (0,)
        assert density.triangles.dtype == np.int64


def test_bad_input_is_refused():
    uv, triangles = square_grid(4)
    rest = bowl(uv)
    expect_refusal(density_change, rest, rest[:-1], triangles, [0])
    expect_refusal(density_change, rest, rest, triangles, [-2])
    expect_refusal(density_change, rest, rest, triangles, [len(triangles)])
    expect_refusal(density_change, rest, np.where(np.isclose(rest, 0.0), np.nan, rest), triangles, [0])
    degenerate = rest.copy()
    degenerate[5] = degenerate[0]  # triangle 0 is (0, 5, 6)
    expect_refusal(density_change, degenerate, rest, triangles, [0])
