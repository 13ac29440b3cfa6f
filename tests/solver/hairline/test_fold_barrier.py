"""The fold barrier against hand values and finite differences."""

import numpy as np
import pytest

from hairport.solver.hairline.fold_barrier import fold_barrier
from hairport.solver.mesh.areas import signed_areas


def test_fold_barrier_against_hand_values_and_differences():
    triangles = np.array([[0, 1, 2], [1, 3, 2]])
    rest = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]])
    rest_areas = signed_areas(rest, triangles)
    weights = np.array([2.0, 3.0])
    energy, gradient, blocks = fold_barrier(triangles, rest, rest_areas, weights)
    assert energy == 0.0 and not gradient.any() and not blocks.any()  # inactive above the threshold
    # squeeze the first triangle to 4 % of its area: -(r - r^)^2 ln(r / r^) by hand
    u = rest.copy()
    u[2] = [0.3, 0.04]
    r = 0.04
    energy, gradient, blocks = fold_barrier(triangles, u, rest_areas, weights)
    assert energy == pytest.approx(2.0 * -((r - 0.1) ** 2) * np.log(r / 0.1), rel=1e-12)
    h = 1e-7
    flat = u.ravel()
    dofs = np.concatenate([2 * triangles[0][:, None] + np.arange(2)]).ravel()

    def at(v):
        return fold_barrier(triangles, v.reshape(-1, 2), rest_areas, weights)

    fd = np.array([(at(flat + h * e)[0] - at(flat - h * e)[0]) / (2 * h) for e in np.eye(len(flat))])
    np.testing.assert_allclose(gradient.ravel(), fd, rtol=1e-6, atol=1e-9)
    fd_hessian = np.array([((at(flat + h * e)[1] - at(flat - h * e)[1]) / (2 * h)).ravel()
                           for e in np.eye(len(flat))])
    np.testing.assert_allclose(blocks[0], fd_hessian[np.ix_(dofs, dofs)], rtol=1e-5, atol=1e-6)
    assert not blocks[1].any()
    # folded: infinite
    u[2] = [0.3, -0.01]
    assert fold_barrier(triangles, u, rest_areas, weights)[0] == np.inf

