"""Projected Newton on the embedded membrane (Eq. 15) with the hairline pinned: edits with
known minimisers, stationarity, load stages and refusals."""

import numpy as np
import pytest

from hairport.solver.hairline.kinks import KINK_BARYCENTRIC
from hairport.solver.hairline.membrane import Membrane, membrane_gradient
from hairport.solver.hairline.newton import ProjectedNewton, relocate
from hairport.solver.mesh.areas import signed_areas
from hairport.solver.model.errors import InputError
from tests.solver.hairline.charts import PARABOLOID, boundary_of, flat_chart, paraboloid_chart, rotated_scalp
from tests.solver.triangle_grids import grid


def assert_unflipped(membrane, u, u_rest):
    signs = np.sign(signed_areas(u_rest, membrane.triangles))
    assert (signed_areas(u, membrane.triangles) * signs > 0).all()


def assert_monotone(report):
    assert np.all(np.diff(report.energy) <= 0.0)


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


def test_a_mirrored_hairline_is_too_far(flat_sheet):
    # the boundary mirrored in x: halfway there the sheet collapses onto the line x = 1/2
    chart, membrane, u_rest, fixed = flat_sheet
    mirrored = np.column_stack([1.0 - u_rest[fixed, 0], u_rest[fixed, 1]])
    with pytest.raises(InputError, match="beyond 50 % of the hairline's motion") as caught:
        relocate(membrane, chart, u_rest, fixed, mirrored, max_iterations=30)
    assert caught.value.code == "hairline_too_far"


def test_relocate_refuses_a_start_degenerate_in_uv(flat_sheet):
    chart, membrane, u_rest, fixed = flat_sheet
    collapsed = u_rest.copy()
    collapsed[12] = collapsed[1]  # interior vertex (1, 1) onto (0, 1): its triangles lose their area
    with pytest.raises(InputError, match="degenerate triangles in uv at the start"):
        relocate(membrane, chart, collapsed, fixed, collapsed[fixed])


def test_stage_starts_by_hand(flat_sheet):
    chart, membrane, u_rest, fixed = flat_sheet
    solver = ProjectedNewton(membrane, chart, u_rest, fixed, u_rest[fixed])
    # an affine hairline motion: the graph-harmonic extension moves every vertex affinely
    # (each inner vertex's six neighbours are symmetric about it), up to the 1e-12 shift
    A, b = np.array([[1.1, 0.2], [-0.1, 0.9]]), np.array([0.05, -0.02])
    extended = solver.harmonic_start(u_rest, u_rest[fixed] @ A.T + b)
    np.testing.assert_allclose(extended[fixed], u_rest[fixed] @ A.T + b, rtol=0, atol=1e-15)
    np.testing.assert_allclose(extended, u_rest @ A.T + b, rtol=0, atol=1e-11)
    # a small translation keeps every triangle: pinned; a 20 % push flips the pinned start
    u, energy, how = solver.stage_start(u_rest, u_rest[fixed] + [0.01, 0.0])
    assert how == "pinned" and energy > 0.0
    np.testing.assert_array_equal(u[~fixed], u_rest[~fixed])
    pushed = u_rest[fixed].copy()
    pushed[:, 0] -= 0.2 * pushed[:, 0] ** 2
    u, energy, how = solver.stage_start(u_rest, pushed)
    assert how == "elastic" and energy == solver.admissible(u)
    assert solver.admissible(np.where(fixed[:, None], u, u_rest)) is None  # the pinned start flips
    assert solver.report.stages == 0  # stage_start does not record; next_stage does
    u, _, reached = solver.next_stage(u_rest, 0.0)
    assert reached == 1.0 and solver.report.stages == 1 and solver.report.start == ["pinned"]
