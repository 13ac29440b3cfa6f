"""The spacing term beyond the paper (solver/adaptation/problem/spacing.py): rest lengths from the source and the
initial transfer, its value, gradient and Hessian in the reference energies, and its switch (weight 0 is
Eq. 1 exactly)."""

import numpy as np
import pytest
import scipy.sparse as sp

from hairport.solver.adaptation.fine.fine_solve import solve_uncoupled
from hairport.solver.adaptation.problem.constraints import BodyDistance
from hairport.solver.adaptation.problem.energies import EnergyWeights, ShapeModel, energy_terms, gradient, hessian
from hairport.solver.adaptation.problem.spacing import (
    band_excess,
    band_excesses,
    spacing_blocks,
    spacing_gradients,
    spacing_residuals,
)
from hairport.solver.adaptation.problem.strand_problem import StrandProblem, group_energies, newton_system
from hairport.solver.mesh.polyline import rest_lengths
from hairport.solver.mesh.query import MeshQuery
from tests.solver.hair_shapes import fine_problem, model_of, outward_strands, sphere_character, tilt_into_surface


def test_rest_lengths_spread_each_strands_stretch_evenly_over_its_source_segments():
    source = np.array([[0, 0, 0], [0, 1, 0], [0, 3, 0], [5, 0, 0], [5, 2, 0], [9, 9, 9], [9, 9, 9]], dtype=float)
    offsets = np.array([0, 3, 5, 7])
    initial = source.copy()
    initial[1:3] *= [1.0, 0.5, 1.0]  # first strand: 3 -> 1.5 long, its segments bunched unevenly (0.5, 1.0)
    initial[4] = [5, 8, 0]  # second strand: 2 -> 8
    rest = rest_lengths(source, initial, offsets)
    np.testing.assert_allclose(rest, [0.5, 1.0, 0.0, 8.0, 0.0, 0.0, 0.0])  # third: no length, no term
    segments = np.array([[0, 1], [1, 2], [3, 4], [5, 6]])
    model = ShapeModel.build(source, segments, sp.csr_matrix((7, 7)))
    np.testing.assert_array_equal(model.rest_lengths(initial), rest[segments[:, 0]])


def test_a_run_of_strands_gets_the_rows_of_the_whole_bit_for_bit():
    rng = np.random.default_rng(3)
    counts = rng.integers(2, 40, 50)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    source = np.cumsum(rng.normal(scale=0.004, size=(offsets[-1], 3)), axis=0)
    initial = source * 1.07 + rng.normal(scale=1e-3, size=source.shape)
    whole = rest_lengths(source, initial, offsets)
    rows = slice(offsets[11], offsets[29])
    run = rest_lengths(source[rows], initial[rows], offsets[11:30] - offsets[11])
    assert np.array_equal(run, whole[rows])


def test_gradient_and_hessian_are_the_energys_derivatives():
    rng = np.random.default_rng(5)
    hair = outward_strands(sphere_character(), n_strands=6, n_points=7, seed=2)
    model = model_of(hair, k=3)
    initial = hair.points + rng.normal(scale=1e-3, size=hair.points.shape)
    points = initial + rng.normal(scale=1e-3, size=hair.points.shape)
    rest = model.rest_lengths(initial)
    weights = EnergyWeights(spacing=2.0, spacing_band=(0.95, 1.05))

    def total(p):
        return energy_terms(model, p, initial, rest=rest, band=weights.spacing_band).total(weights)

    g = gradient(model, points, initial, weights, rest=rest)
    h = 1e-7
    for i, a in [(1, 0), (3, 2), (9, 1), (20, 2)]:
        up, down = points.copy(), points.copy()
        up[i, a] += h
        down[i, a] -= h
        assert g[i, a] == pytest.approx((total(up) - total(down)) / (2 * h), rel=1e-5, abs=1e-6)
    # Eq. 1's gradient plus exactly the term's own
    g0 = gradient(model, points, initial, EnergyWeights(), rest=rest)
    length = np.linalg.norm(model.D @ points, axis=1)
    unit = (model.D @ points) / length[:, None]
    np.testing.assert_allclose(g - g0, model.D.T @ spacing_gradients(unit, length, rest, 2.0, (0.95, 1.05)), atol=1e-9)
    assert np.abs(g - g0).max() > 1e-3  # some segments lie outside the band
    H = hessian(model, points, weights, rest=rest) - hessian(model, points, EnergyWeights(), rest=rest)
    assert abs(H - H.T).max() < 1e-6
    assert H.nnz > 0


def test_the_terms_blocks_are_the_exact_hessian_when_stretched_and_never_indefinite():
    rng = np.random.default_rng(1)
    e = rng.normal(scale=0.004, size=(200, 3))
    length = np.linalg.norm(e, axis=1)
    unit = e / length[:, None]
    rest = length * rng.uniform(0.5, 1.5, 200)
    blocks = spacing_blocks(unit, length, rest, 1.5)
    assert np.linalg.eigvalsh(blocks).min() >= -1e-9 * np.abs(blocks).max()
    stretched = np.flatnonzero(length > rest)[:5]
    h = 1e-9
    for m in stretched:
        for a in range(3):
            shifted = e[m].copy()
            shifted[a] += h
            n = np.linalg.norm(shifted)
            numeric = (spacing_gradients((shifted / n)[None], np.array([n]), rest[m:m + 1], 1.5)[0]
                       - spacing_gradients(unit[m:m + 1], length[m:m + 1], rest[m:m + 1], 1.5)[0]) / h
            np.testing.assert_allclose(blocks[m][:, a], numeric, rtol=1e-4, atol=1e-6 * np.abs(blocks[m]).max())


def test_weight_zero_is_eq1_exactly_and_a_problem_without_rest_lengths_refuses_the_term():
    source = sphere_character()
    query = MeshQuery(source.vertices, source.faces)
    hair = outward_strands(source, n_strands=12, n_points=10, seed=4)
    start = tilt_into_surface(hair, query, np.radians(93.0))
    with_rest = fine_problem(hair, start, np.ones(hair.n_particles), hair.points)
    bare = StrandProblem(*[getattr(with_rest, name) for name in
                           ("offsets", "source_directions", "initial", "coupling", "features", "gamma", "fixed")])
    eq1 = EnergyWeights()
    a, _ = solve_uncoupled(with_rest, BodyDistance(query), eq1)
    b, _ = solve_uncoupled(bare, BodyDistance(query), eq1)
    assert np.array_equal(a, b)
    on = EnergyWeights(spacing=1.0)
    spaced, report = solve_uncoupled(with_rest, BodyDistance(query), on)
    assert report.converged and np.abs(spaced - a).max() > 1e-5  # the term moves the optimum
    with pytest.raises(ValueError, match="no rest lengths"):
        newton_system(bare, start, on, np.ones(hair.n_particles))
    with pytest.raises(ValueError, match="no rest lengths"):
        group_energies(bare, start, on, bare.strand_of, bare.n_strands)
    with pytest.raises(ValueError, match="no rest lengths"):
        solve_uncoupled(bare, BodyDistance(query), on)


def test_a_free_band_leaves_segments_within_it_untouched_and_prices_the_excess():
    length = np.array([0.8, 0.9, 1.0, 1.1, 1.3, 2.0]) * 0.004
    rest = np.full(6, 0.004)
    excess = spacing_residuals(length, rest, (0.85, 1.18))
    np.testing.assert_allclose(excess, [-0.05, 0.0, 0.0, 0.0, 0.12, 0.82], atol=1e-12)
    unit = np.tile([0.0, 1.0, 0.0], (6, 1))
    blocks = spacing_blocks(unit, length, rest, 2.0, (0.85, 1.18))
    assert np.abs(blocks[1:4]).max() == 0.0 and np.abs(spacing_gradients(unit, length, rest, 2.0, (0.85, 1.18))[1:4]).max() == 0.0
    assert blocks[0, 1, 1] == pytest.approx(2.0 * 2.0 / 0.004**2)  # below: radial stiffness only
    assert blocks[0, 0, 0] == 0.0
    assert blocks[4, 0, 0] == pytest.approx(2.0 * 2.0 * 0.12 / (0.004 * length[4]))  # above: tangential too
    for ratio, low, high in [(0.8, 0.85, 1.18), (1.0, 0.85, 1.18), (1.5, 0.85, 1.18), (1.3, 1.0, 1.0)]:
        assert band_excess(ratio, low, high) == pytest.approx(band_excesses(np.array([ratio]), low, high)[0])
