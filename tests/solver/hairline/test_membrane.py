"""The embedded neo-Hookean scalp membrane (Section 6.1, Eq. 15-17) against hand values and
finite differences."""

import numpy as np
import pytest
import scipy.sparse as sp

from hairport.solver.hairline.membrane import (
    DEFAULT_LAM,
    DEFAULT_MU,
    Membrane,
    assemble_blocks,
    deformation_gradients,
    energy_density,
    membrane_energy,
    membrane_gradient,
    membrane_hessian,
    parameter_blocks,
    position_gradients,
    project_psd,
    shifted_solve,
)
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


# ----------------------------------------------------------------------------------------
# assembly helpers
# ----------------------------------------------------------------------------------------


def test_project_psd_clamps_negative_eigenvalues():
    rotation = np.array([[0.6, -0.8], [0.8, 0.6]])
    block = rotation @ np.diag([3.0, -2.0]) @ rotation.T
    projected = project_psd(np.stack([block, np.eye(2)]))
    np.testing.assert_allclose(projected[0], rotation @ np.diag([3.0, 0.0]) @ rotation.T, rtol=0, atol=1e-14)
    np.testing.assert_allclose(projected[1], np.eye(2), rtol=0, atol=1e-15)


def test_assemble_blocks_sums_over_shared_corners():
    triangles = np.array([[0, 1, 2], [2, 1, 3]])
    blocks = np.stack([np.full((6, 6), 1.0), np.full((6, 6), 10.0)])
    matrix = assemble_blocks(triangles, blocks, 4).toarray()
    assert matrix.shape == (8, 8)
    # parameters 2..5 belong to vertices 1 and 2, shared: 1 + 10; vertex 0 only in the first,
    # vertex 3 only in the second, and they never meet
    assert matrix[2, 5] == 11.0 and matrix[0, 1] == 1.0 and matrix[6, 7] == 10.0 and matrix[0, 6] == 0.0
    assert matrix.sum() == 36.0 + 360.0


def test_shifted_solve_regularises_a_singular_matrix():
    H = sp.csr_matrix(np.diag([4.0, 2.0, 0.0]))
    solution = shifted_solve(H, np.array([4.0, 2.0, 0.0]))
    np.testing.assert_allclose(solution, [1.0, 1.0, 0.0], rtol=1e-9, atol=0)
    # the null direction sees only the shift, 1e-10 of the largest diagonal entry (4)
    np.testing.assert_allclose(shifted_solve(H, np.array([0.0, 0.0, 1.0])), [0.0, 0.0, 2.5e9], rtol=1e-9)


def test_position_gradients_are_the_gradient_in_space(perturbed):
    chart, membrane, u = perturbed
    host, _ = chart.locate(u)
    F, gradient = position_gradients(membrane, chart.embed(u))
    np.testing.assert_array_equal(F, deformation_gradients(membrane, chart.embed(u)))
    np.testing.assert_allclose(np.einsum("nia,ni->na", chart.jacobians(host), gradient),
                               membrane_gradient(membrane, chart, u), rtol=0, atol=1e-15)
    # Hessian blocks, assembled unprojected, are the exact Hessian
    blocks = parameter_blocks(membrane, F, chart.jacobians(host))
    np.testing.assert_allclose(assemble_blocks(membrane.triangles, blocks, len(u)).toarray(),
                               membrane_hessian(membrane, chart, u, project=False).toarray(), rtol=0, atol=0)
