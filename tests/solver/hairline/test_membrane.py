"""The embedded neo-Hookean scalp membrane (Section 6.1, Eq. 15-19) against hand values,
finite differences, a brute-force locator and edits with known minimisers."""

import numpy as np
import pytest

from hairport.solver.hairline.head_chart import HeadChart
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
    signed_uv_areas,
)
from hairport.solver.hairline.newton import KINK_BARYCENTRIC, relocate
from hairport.solver.model.errors import InputError

PARABOLOID = 0.3  # head z = PARABOLOID (x^2 + y^2), uv = (x, y)


def grid(nx, ny, x0, x1, y0, y1):
    """Vertices ``((nx+1)(ny+1), 2)`` and ``2 nx ny`` counter-clockwise triangles of a grid."""
    xs, ys = np.meshgrid(np.linspace(x0, x1, nx + 1), np.linspace(y0, y1, ny + 1), indexing="ij")
    points = np.column_stack([xs.ravel(), ys.ravel()])
    index = np.arange((nx + 1) * (ny + 1)).reshape(nx + 1, ny + 1)
    a, b, c, d = index[:-1, :-1].ravel(), index[1:, :-1].ravel(), index[1:, 1:].ravel(), index[:-1, 1:].ravel()
    return points, np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])


def paraboloid_chart(cells=16):
    uv, faces = grid(cells, cells, -1.0, 1.0, -1.0, 1.0)
    return HeadChart.build(np.column_stack([uv, PARABOLOID * (uv**2).sum(axis=1)]), faces, uv)


def flat_chart(cells=12):
    uv, faces = grid(cells, cells, -0.5, 1.5, -0.5, 1.5)
    return HeadChart.build(np.column_stack([uv, np.zeros(len(uv))]), faces, uv)


def rotated_scalp(chart, cells=6):
    """A small scalp grid, rotated and shifted so its vertices avoid the head's edges."""
    u, triangles = grid(cells, cells, -0.5, 0.5, -0.5, 0.5)
    c, s = np.cos(0.3), np.sin(0.3)
    u = u @ np.array([[c, s], [-s, c]]) + 0.013
    return Membrane.build(chart.embed(u), triangles), u


def boundary_of(u, low, high):
    return (np.isclose(u, low) | np.isclose(u, high)).any(axis=1)


def assert_unflipped(membrane, u, u_rest):
    signs = np.sign(signed_uv_areas(membrane.triangles, u_rest))
    assert (signed_uv_areas(membrane.triangles, u) * signs > 0).all()


def assert_monotone(report):
    assert np.all(np.diff(report.energy) <= 0.0)


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
    rest_areas = signed_uv_areas(triangles, rest)
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


# ----------------------------------------------------------------------------------------
# chart
# ----------------------------------------------------------------------------------------


def test_locator_matches_a_brute_force_scan():
    rng = np.random.default_rng(7)
    uv, faces = grid(10, 10, 0.0, 2.0, 0.0, 1.0)  # 200 triangles
    inner = ~boundary_of(uv, 0.0, 1.0) & ~np.isclose(uv[:, 0], 2.0)
    uv[inner] += rng.uniform(-0.03, 0.03, size=(inner.sum(), 2))
    chart = HeadChart.build(np.column_stack([uv, np.sin(uv[:, 0])]), faces, uv)
    points = rng.uniform([-0.2, -0.2], [2.2, 1.2], size=(2000, 2))
    host, barycentric = chart.locate(points)

    corners = uv[faces]  # brute force: barycentric coordinates in every triangle
    edges = np.stack([corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]], axis=2)
    local = np.einsum("tab,ptb->pta", np.linalg.inv(edges), points[:, None, :] - corners[None, :, 0])
    weights = np.concatenate([1.0 - local.sum(axis=2, keepdims=True), local], axis=2)
    inside = (weights >= 0).all(axis=2)
    assert inside.sum(axis=1).max() == 1
    expected = np.where(inside.any(axis=1), inside.argmax(axis=1), -1)
    np.testing.assert_array_equal(host, expected)
    found = expected >= 0
    assert 0 < (~found).sum() < len(points)
    np.testing.assert_allclose(barycentric[found], weights[found, expected[found]], rtol=0, atol=1e-12)
    assert np.isnan(barycentric[~found]).all()
    with pytest.raises(ValueError):
        chart.embed(points)


def test_embed_and_jacobians_follow_the_host_triangle():
    chart = paraboloid_chart()
    u = np.random.default_rng(1).uniform(-0.9, 0.9, size=(50, 2))
    host, barycentric = chart.locate(u)
    x = chart.embed(u)
    np.testing.assert_allclose(x[:, :2], u, rtol=0, atol=1e-14)
    np.testing.assert_allclose(x[:, 2], np.einsum("nk,nk->n", barycentric, chart.vertices[chart.faces[host], 2]), atol=1e-14)
    h = 1e-7
    J = chart.jacobians(host)
    for a in range(2):
        step = np.zeros(2)
        step[a] = h
        assert (chart.locate(u + step)[0] == host).all()
        np.testing.assert_allclose((chart.embed(u + step) - chart.embed(u - step)) / (2 * h), J[:, :, a], atol=1e-8)


# ----------------------------------------------------------------------------------------
# relocation
# ----------------------------------------------------------------------------------------


def test_identity_edit_keeps_the_rest_state():
    chart = paraboloid_chart()
    membrane, u_rest = rotated_scalp(chart)
    fixed = np.zeros(len(u_rest), dtype=bool)
    fixed[[0, 6, 42, 48, 3, 21, 27, 45]] = True  # corners and side midpoints of the 7x7 grid
    u, report = relocate(membrane, chart, u_rest, fixed, u_rest[fixed])
    assert report.converged and report.iterations <= 1
    np.testing.assert_allclose(u, u_rest, rtol=0, atol=1e-9)


@pytest.fixture(scope="module")
def flat_sheet():
    chart = flat_chart()
    u_rest, triangles = grid(10, 10, 0.0, 1.0, 0.0, 1.0)
    membrane = Membrane.build(np.column_stack([u_rest, np.zeros(len(u_rest))]), triangles)
    return chart, membrane, u_rest, boundary_of(u_rest, 0.0, 1.0)


def test_flat_scaling_edit_reaches_the_scaled_sheet(flat_sheet):
    chart, membrane, u_rest, fixed = flat_sheet
    centre = np.array([0.5, 0.5])
    scaled = centre + 1.2 * (u_rest - centre)  # uniform F = 1.2 I: the exact minimiser
    u, report = relocate(membrane, chart, u_rest, fixed, scaled[fixed])
    assert report.converged and report.stages == 1 and report.start == ["pinned"]
    assert report.iterations <= 8
    assert_monotone(report)
    assert_unflipped(membrane, u, u_rest)
    np.testing.assert_allclose(u, scaled, rtol=0, atol=1e-6)


def test_flat_push_edit_converges_to_a_stationary_point(flat_sheet):
    chart, membrane, u_rest, fixed = flat_sheet
    target = u_rest[fixed].copy()
    target[:, 0] -= 0.2 * target[:, 0] ** 2  # the side x = 1 pushed in by 20 %, smoothly
    u, report = relocate(membrane, chart, u_rest, fixed, target)
    assert report.converged and report.iterations <= 8
    assert report.start == ["elastic"]  # pinning alone flips the triangles at x = 1
    assert_monotone(report)
    assert_unflipped(membrane, u, u_rest)
    np.testing.assert_array_equal(u[fixed], target)
    assert np.abs(membrane_gradient(membrane, chart, u)[~fixed]).max() < 1e-8
    # Young's modulus only scales the energy
    stiff = Membrane.build(membrane.rest, membrane.triangles, young=1000.0)
    u_stiff, _ = relocate(stiff, chart, u_rest, fixed, target)
    np.testing.assert_allclose(u_stiff, u, rtol=0, atol=1e-9)


@pytest.mark.parametrize("edit", ["scale", "push"])
def test_curved_edits_stay_on_the_head(edit):
    chart = paraboloid_chart()
    u_rest, triangles = grid(10, 10, -0.5, 0.5, -0.5, 0.5)
    membrane = Membrane.build(chart.embed(u_rest), triangles)
    fixed = boundary_of(u_rest, -0.5, 0.5)
    target = 1.2 * u_rest[fixed] if edit == "scale" else u_rest[fixed] - [[0.2, 0.0]] * (u_rest[fixed, :1] + 0.5) ** 2
    u, report = relocate(membrane, chart, u_rest, fixed, target, energy_tolerance=0.0)
    assert report.converged and report.iterations <= 15 and report.stop in ("step", "decrement")
    assert_monotone(report)
    assert_unflipped(membrane, u, u_rest)
    np.testing.assert_array_equal(u[fixed], target)
    # on the head: x, y = u and z on the plane of the host triangle of the paraboloid mesh
    x = chart.embed(u)
    host, barycentric = chart.locate(u)
    np.testing.assert_allclose(x[:, :2], u, rtol=0, atol=1e-12)
    assert np.abs(x[:, 2] - np.einsum("nk,nk->n", barycentric, chart.vertices[chart.faces[host], 2])).max() < 1e-12
    # the flat interpolation lies above the paraboloid by at most its curvature times h^2
    gap = x[:, 2] - PARABOLOID * (u**2).sum(axis=1)
    assert gap.min() > -1e-12 and gap.max() < PARABOLOID * (2.0 / 16) ** 2
    # stationary: free vertices inside a head triangle have no gradient left
    interior = ~fixed & (barycentric.min(axis=1) > KINK_BARYCENTRIC)
    assert np.abs(membrane_gradient(membrane, chart, u)[interior]).max() < 1e-8
    # the default stops once a step lowers the energy by less than 1e-7 of it, earlier, at
    # parameters within 5e-5 of the converged ones: 2.5e-5 of the chart's 2-unit width,
    # a few micrometres on a 20 cm head patch
    early, early_report = relocate(membrane, chart, u_rest, fixed, target)
    assert early_report.converged and early_report.iterations <= report.iterations
    assert early_report.stop == "energy" and np.abs(early - u).max() < 5e-5


def test_large_dent_is_reached_in_load_stages(flat_sheet):
    chart, membrane, u_rest, fixed = flat_sheet
    target = u_rest[fixed].copy()
    y = target[:, 1] - 0.5
    target[:, 0] -= 0.8 * (target[:, 0] > 0.9) * (1.0 - 4.0 * y**2) ** 2  # an 80 % dent into side x = 1
    u, report = relocate(membrane, chart, u_rest, fixed, target)
    assert report.converged and report.stages > 1 and set(report.start) == {"elastic"}
    assert_unflipped(membrane, u, u_rest)
    np.testing.assert_array_equal(u[fixed], target)


def test_relocate_refuses_targets_outside_the_chart(flat_sheet):
    chart, membrane, u_rest, fixed = flat_sheet
    with pytest.raises(InputError):
        relocate(membrane, chart, u_rest, fixed, u_rest[fixed] + 10.0)
    with pytest.raises(InputError):
        relocate(membrane, chart, u_rest, fixed, u_rest[fixed][:-1])
