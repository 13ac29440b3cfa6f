"""The embedded neo-Hookean scalp membrane (Section 6.1, Eq. 15-17) against hand values and
finite differences."""

import numpy as np
import pytest

from hairport.solver.hairline.membrane import (
    DEFAULT_LAM,
    DEFAULT_MU,
    Membrane,
    deformation_gradients,
    energy_density,
    fold_barrier,
    membrane_energy,
    membrane_gradient,
    membrane_hessian,
)
from hairport.solver.mesh.areas import signed_areas
from tests.solver.hairline.charts import paraboloid_chart, rotated_scalp

# ----------------------------------------------------------------------------------------
# material
# ----------------------------------------------------------------------------------------


def test_lame_parameters_are_the_membrane_ones():
    membrane = Membrane.build(np.eye(3), [[0, 1, 2]], young=2.0, poisson=0.3)
    assert membrane.mu == pytest.approx(2.0 / 2.6, rel=1e-15)
    assert membrane.lam == pytest.approx(2.0 * 0.3 / 0.91, rel=1e-15)  # plane stress
    assert membrane.areas[0] == pytest.approx(np.sqrt(3.0) / 2.0, rel=1e-15)  # equilateral, side sqrt 2


def test_uniaxial_stretch_by_hand():
    rng = np.random.default_rng(3)
    rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    F = (rotation[:, :2] @ np.diag([2.0, 1.0]))[None]  # stretched 2x along one edge, in 3D
    mu, lam = 0.7, 1.3
    # C = diag(4, 1): tr C - 2 = 3, J = 2
    expected = 0.5 * mu * 3.0 - mu * np.log(2.0) + 0.5 * lam * np.log(2.0) ** 2
    assert energy_density(F, mu, lam)[0] == pytest.approx(expected, rel=1e-14)
    assert energy_density(F)[0] == pytest.approx(
        1.5 * DEFAULT_MU - DEFAULT_MU * np.log(2.0) + 0.5 * DEFAULT_LAM * np.log(2.0) ** 2, rel=1e-14
    )
    collapsed = np.array([[[1.0, 2.0], [0.0, 0.0], [0.0, 0.0]], [[np.nan, 0.0], [0.0, 1.0], [0.0, 0.0]]])
    assert np.isinf(energy_density(collapsed)).all()


def test_rest_state_is_an_isometry_with_zero_energy_and_gradient():
    chart = paraboloid_chart()
    membrane, u = rotated_scalp(chart)
    F = deformation_gradients(membrane, chart.embed(u))
    np.testing.assert_allclose(np.einsum("mia,mib->mab", F, F), np.broadcast_to(np.eye(2), (len(F), 2, 2)), atol=1e-12)
    assert np.abs(energy_density(F, membrane.mu, membrane.lam)).max() < 1e-12
    assert abs(membrane_energy(membrane, chart, u)) < 1e-12
    assert np.abs(membrane_gradient(membrane, chart, u)).max() < 1e-10


# ----------------------------------------------------------------------------------------
# derivatives
# ----------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def perturbed():
    chart = paraboloid_chart()
    membrane, u_rest = rotated_scalp(chart)
    u = u_rest + np.random.default_rng(0).normal(scale=0.01, size=u_rest.shape)
    return chart, membrane, u


def test_gradient_matches_central_differences(perturbed):
    chart, membrane, u = perturbed
    h = 1e-6
    hosts = chart.locate(u)[0]
    fd = np.zeros_like(u)
    for i in range(len(u)):
        for a in range(2):
            step = np.zeros_like(u)
            step[i, a] = h
            assert (chart.locate(u + step)[0] == hosts).all() and (chart.locate(u - step)[0] == hosts).all()
            fd[i, a] = (membrane_energy(membrane, chart, u + step) - membrane_energy(membrane, chart, u - step)) / (2 * h)
    g = membrane_gradient(membrane, chart, u)
    assert np.linalg.norm(fd - g) < 1e-6 * np.linalg.norm(g)


def test_hessian_matches_differences_of_the_gradient(perturbed):
    chart, membrane, u = perturbed
    h = 1e-6
    H = membrane_hessian(membrane, chart, u, project=False)
    assert H.shape == (2 * len(u), 2 * len(u))
    H = H.toarray()
    fd = np.zeros_like(H)
    for i in range(len(u)):
        for a in range(2):
            step = np.zeros_like(u)
            step[i, a] = h
            fd[:, 2 * i + a] = (
                membrane_gradient(membrane, chart, u + step) - membrane_gradient(membrane, chart, u - step)
            ).ravel() / (2 * h)
    assert np.linalg.norm(fd - H) < 1e-5 * np.linalg.norm(H)
    np.testing.assert_allclose(H, H.T, rtol=0, atol=1e-12 * np.abs(H).max())


def test_projected_hessian_is_positive_semidefinite(perturbed):
    chart, membrane, u = perturbed
    compressed = 0.6 * u  # squeezed scalp: the exact per-triangle Hessians are indefinite
    for state in (u, compressed):
        w = np.linalg.eigvalsh(membrane_hessian(membrane, chart, state).toarray())
        assert w.min() >= -1e-9 * w.max()
    exact = np.linalg.eigvalsh(membrane_hessian(membrane, chart, compressed, project=False).toarray())
    assert exact.min() < -1e-6 * exact.max()


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

