"""The multi-scale solve (solver/adaptation/multiscale.py, Eq. 14): agreement with the coupled solve, chunking, workers, progress."""

import numpy as np
import pytest

from hairport.solver import pipeline
from hairport.solver.adaptation.loop.options import SolveOptions
from hairport.solver.adaptation.multiscale import (
    COARSE_PROGRESS_SHARE,
    build_multiscale_model,
    chunk_strands,
    fine_source,
    solve_multiscale,
)
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.hair import particle_indices
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import PRESETS, build_character
from tests.solver.hair_shapes import outward_strands, parallel_strands, sphere_character

EPS_C = 5e-4


def test_chunks_are_consecutive_whole_strands_within_the_budget():
    counts = np.array([3, 4, 2, 10, 1, 1, 5])
    chunks = chunk_strands(counts, 6)
    assert [c.tolist() for c in chunks] == [[0], [1, 2], [3], [4, 5], [6]]
    assert np.array_equal(np.concatenate(chunks), np.arange(len(counts)))
    assert chunk_strands(np.array([], dtype=np.int64), 5) == []
    assert [c.tolist() for c in chunk_strands(counts, 1000)] == [list(range(7))]


@pytest.fixture(scope="module")
def case():
    """Average female -> heavy male, a 150-strand fringe, half the strands guides."""
    source = build_character(PRESETS["average-female"])
    target = build_character(PRESETS["heavy-male"])
    hair = generate_groom(source, "fringe", 150, 40, seed=0)
    adaptable = pipeline.preprocess(source, hair, pipeline.PreprocessOptions(guides=75))
    multiscale = pipeline.retarget(adaptable, target, pipeline.RetargetOptions(method="multiscale", workers=1))
    return source, target, hair, adaptable, multiscale


def test_multiscale_is_close_to_the_global_solve(case):
    _, target, hair, adaptable, multiscale = case
    coupled = pipeline.retarget(adaptable, target, pipeline.RetargetOptions(method="global"))
    distance = np.linalg.norm(multiscale.hair.points - coupled.hair.points, axis=1).mean()
    assert distance <= 2e-3, distance  # measured 1.4 mm
    assert coupled.metrics["penetrating_particles"] == 0


def test_multiscale_result_is_penetration_free_with_exact_roots(case):
    _, target, hair, adaptable, multiscale = case
    sd = MeshQuery(target.vertices, target.faces).signed_distance(multiscale.hair.points[~hair.is_root]).distance
    assert (sd < 0).sum() == 0
    assert sd.min() >= EPS_C - 1e-5
    assert multiscale.metrics["root_to_target_max"] <= 1e-12
    assert multiscale.metrics["root_to_surface_max"] <= 1e-5
    report = multiscale.solve
    assert report.guides == 75 and report.chunks == 1
    assert sum(f.groups for f in report.fine) == 75  # the normal strands, each its own problem


def test_guides_move_only_in_the_coarse_solve(case):
    """The fine level leaves guide particles where the coarse level put them."""
    _, target, hair, adaptable, multiscale = case
    guides = particle_indices(hair.offsets, adaptable.multiscale.guides)
    options = pipeline.RetargetOptions(method="multiscale", workers=1, chunk_particles=1)
    chunked = pipeline.retarget(adaptable, target, options)
    np.testing.assert_array_equal(chunked.hair.points[guides], multiscale.hair.points[guides])
    # strands are independent: chunks of one strand give the same result
    assert chunked.solve.chunks == 75
    np.testing.assert_allclose(chunked.hair.points, multiscale.hair.points, rtol=0, atol=1e-12)


def test_parallel_workers_give_the_same_result(case):
    _, target, hair, adaptable, multiscale = case
    options = pipeline.RetargetOptions(method="multiscale", workers=2, chunk_particles=1000)
    parallel = pipeline.retarget(adaptable, target, options)
    assert parallel.solve.workers == 2 and parallel.solve.chunks >= 2
    np.testing.assert_allclose(parallel.hair.points, multiscale.hair.points, rtol=0, atol=1e-12)


def test_progress_of_the_coarse_then_the_fine_level(case):
    """Guides' iterations in [0, 0.5] as ``guides: ...``, then one report per fine chunk up to 1."""
    _, target, hair, adaptable, _ = case
    prepared = pipeline.prepare_target(adaptable, target)
    initial, _ = pipeline.initial_transfer(adaptable, prepared)
    seen = []
    options = SolveOptions(max_iterations=3)
    _, report = solve_multiscale(
        hair, adaptable.multiscale, adaptable.coarse_model, adaptable.fine_source, initial,
        MeshQuery(prepared.vertices, prepared.faces), options=options, chunk_particles=1000,
        progress=lambda *call: seen.append(call),
    )
    coarse = report.coarse
    assert COARSE_PROGRESS_SHARE == 0.5 and report.chunks >= 2
    assert seen == [
        ("solve", 0.5 * k / 3, f"guides: iteration {k}: max step {step:.2e} m, {n} open")
        for k, step, n in zip(range(1, coarse.iterations + 1), coarse.max_step,
                              coarse.open_groups[1:] + [coarse.groups - coarse.converged_groups])
    ] + [("solve", 0.5 + 0.5 * i / report.chunks, f"strands: chunk {i}/{report.chunks}")
         for i in range(1, report.chunks + 1)]



def test_fine_rows_with_fewer_guide_particles_than_k_pull_towards_those_found():
    hair = parallel_strands(n_strands=3, n_points=3, spacing=0.01)
    model = build_multiscale_model(hair, 1, 5)  # one guide: 3 candidate particles for k = 5
    fine = fine_source(hair, model)
    nb = model.fine_neighbours
    assert len(fine.particles) == 6 and (np.count_nonzero(nb.weight, axis=1) == 3).all()
    np.testing.assert_allclose(fine.pull_weight, 1.0, atol=1e-15)
    expected = hair.points[fine.particles] - np.einsum("nk,nkd->nd", nb.weight, hair.points[nb.index])
    np.testing.assert_allclose(fine.source_features, expected, atol=1e-15)


def test_a_single_strand_has_no_inter_strand_term_and_retargets():
    source, target = sphere_character(), sphere_character(scale=(1.1, 1.0, 1.05))
    hair = outward_strands(source, n_strands=1, n_points=30)
    adaptable = pipeline.preprocess(source, hair)
    assert abs(adaptable.coarse_model.K).sum() == 0.0 and len(adaptable.fine_source.strands) == 0
    result = pipeline.retarget(adaptable, target, pipeline.RetargetOptions(workers=1))
    assert result.metrics["penetrating_particles"] == 0
    assert result.metrics["interstrand_error_m"] == 0.0
    assert result.metrics["root_to_target_max"] <= 1e-12
    assert np.isfinite(result.hair.points).all()


def test_the_report_counts_how_many_iterations_the_fine_strands_took(case):
    _, target, hair, adaptable, multiscale = case
    spread = multiscale.solve.fine_iterations()
    fine = multiscale.solve.fine[0]
    assert spread["strands"] == 75 == sum(fine.stopped) + fine.capped  # every normal strand, once
    assert 1 <= spread["p50"] <= spread["p90"] <= spread["p99"] <= spread["max"] == fine.iterations
    assert spread["capped"] == fine.capped == fine.groups - fine.converged_groups
    # with a cap of 3 iterations, the strands still open after the third are counted as capped, at 3
    capped = pipeline.retarget(adaptable, target, pipeline.RetargetOptions(method="multiscale", workers=1,
                                                                           max_iterations=3))
    spread = capped.solve.fine_iterations()
    assert spread["max"] == 3 and spread["capped"] > 0 and spread["strands"] == 75
