"""Tests for solver/wrap/result.py: the residual of a wrap and its refusal."""

from __future__ import annotations

import numpy as np
import pytest

from hairport.solver.model.errors import InputError
from hairport.solver.wrap.result import (
    MAX_RESIDUAL_MEAN_M,
    MAX_RESIDUAL_P95_M,
    MIN_COVERAGE,
    MIN_NORMAL_AGREEMENT,
    Residual,
    SurfaceResidual,
    WrapResult,
    check_wrap,
    sample_surface,
    surface_residual,
)
from hairport.solver.wrap.surface import TargetSurface
from tests.solver.wrap.conftest import grid, sphere

COSINE = np.cos(np.radians(60.0))


def test_residual_statistics():
    r = Residual.of(np.arange(101) * 1e-4)
    assert (r.mean, r.p95, r.max, r.count) == (pytest.approx(5e-3), pytest.approx(9.5e-3), pytest.approx(1e-2), 101)
    assert "mean 5.00 mm, p95 9.50 mm, max 10.00 mm" == r.millimetres()
    assert np.isnan(Residual.of(np.zeros(0)).mean)


def test_samples_lie_on_the_surface_and_repeat_with_the_seed():
    vertices, faces = sphere(0.1, 3)
    samples = sample_surface(vertices, faces, 500)
    radius = np.linalg.norm(samples, axis=1)
    assert radius.max() <= 0.1 + 1e-12 and radius.min() > 0.098
    np.testing.assert_array_equal(samples, sample_surface(vertices, faces, 500))


def test_a_patch_on_the_target_has_no_residual_and_uncovered_target_does_not_count():
    vertices, faces = sphere(0.1, 3)
    surface = TargetSurface(vertices, faces)
    exact = surface_residual(vertices, faces, surface, COSINE)
    assert exact.symmetric.max < 1e-12 and exact.coverage == 1.0 and exact.agreement == 1.0
    # a cap of the sphere (the upper third) as the patch: the rest of the target is uncovered
    cap = np.flatnonzero((vertices[faces][:, :, 1] > 0.03).all(axis=1))
    ids, local = np.unique(faces[cap], return_inverse=True)
    part = surface_residual(vertices[ids], local.reshape(-1, 3), surface, COSINE)
    assert part.symmetric.max < 1e-12 and part.from_target.count < 0.5 * exact.from_target.count
    # a patch 3 mm off the surface
    off = surface_residual(vertices * 1.03, faces, surface, COSINE)
    assert abs(off.to_target.mean - 3e-3) < 1e-4


def test_a_patch_past_a_cut_is_not_covered():
    vertices, faces = grid(11, 0.1)
    surface = TargetSurface(vertices, faces)
    shifted = vertices + [0.05, 0.0, 0.001]  # half of the patch past the target's right edge
    residual = surface_residual(shifted, faces, surface, COSINE)
    # covered: the 5 x 9 vertices over the target's inside (those over its rim project onto the rim)
    assert residual.coverage == pytest.approx(45 / 121)
    assert residual.to_target.max == pytest.approx(1e-3)


def _result(mean=1e-4, p95=3e-4, coverage=1.0, agreement=1.0) -> WrapResult:
    residual = Residual(mean, p95, 10 * p95, 100)
    return WrapResult(np.zeros((3, 3)), np.ones(3, bool), SurfaceResidual(residual, residual, residual, coverage,
                                                                           agreement))


@pytest.mark.parametrize("bad, words", [
    (dict(mean=1.5 * MAX_RESIDUAL_MEAN_M, p95=1.5 * MAX_RESIDUAL_MEAN_M), "mean above"),
    (dict(p95=1.5 * MAX_RESIDUAL_P95_M), "p95 above"),
    (dict(agreement=MIN_NORMAL_AGREEMENT - 0.1), "normals"),
    (dict(coverage=MIN_COVERAGE / 2), "found target surface"),
    (dict(mean=float("nan")), "mean above"),
])
def test_check_wrap_refuses_with_the_residual_in_the_message(bad, words):
    check_wrap(_result())
    with pytest.raises(InputError) as error:
        check_wrap(_result(**bad), "target.obj")
    assert error.value.code == "wrap_failed" and error.value.source == "target.obj"
    assert words in error.value.problem and "mm" in error.value.problem
