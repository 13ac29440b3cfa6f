"""The head chart of Eq. 18-19: its point locator against a brute-force scan, the embedding
and its Jacobians."""

import numpy as np
import pytest

from hairport.solver.hairline.head_chart import HeadChart
from tests.solver.hairline.charts import boundary_of, paraboloid_chart
from tests.solver.triangle_grids import grid


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



def test_place_is_locate_and_embed():
    chart = paraboloid_chart()
    u = np.array([[0.1, -0.2], [0.5, 0.5], [3.0, 0.0]])  # the last outside the [-1, 1]^2 chart
    host, barycentric, x = chart.place(u)
    expected_host, expected_barycentric = chart.locate(u)
    np.testing.assert_array_equal(host, expected_host)
    np.testing.assert_array_equal(barycentric, expected_barycentric)
    assert host[2] == -1 and np.isnan(x[2]).all()
    np.testing.assert_array_equal(x[:2], chart.embed(u[:2]))
    np.testing.assert_allclose(x[:2, :2], u[:2], rtol=0, atol=1e-15)
