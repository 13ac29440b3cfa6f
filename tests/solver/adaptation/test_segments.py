"""Whole strands outside the body: the solves clear the segments that dip into it (solver/adaptation/segments.py)."""

import numpy as np
import pytest
import scipy.sparse as sp

from hairport.solver.adaptation.loop.options import SolveOptions
from hairport.solver.adaptation.problem.constraints import BodyDistance
from hairport.solver.adaptation.problem.energies import EnergyWeights
from hairport.solver.adaptation.problem.strand_problem import group_energies, problem_from_shape_model
from hairport.solver.adaptation.segments import (
    MAX_MARGIN,
    lift_margins,
    segment_windows,
    welded_maximum,
    welded_run_ids,
    window_problem,
)
from hairport.solver.adaptation.solve import solve_hairstyle, solve_strands
from hairport.solver.mesh.collision import collision_query
from hairport.solver.mesh.segment_crossing import SegmentCrossings, crossing_segments
from hairport.solver.metrics import mean_segment_angle
from hairport.solver.model.hair import Hair
from tests.solver.hair_shapes import fine_problem, model_of
from tests.solver.mesh.meshes import icosphere

#: a shoulder-like curvature (m) ...
RADIUS = 0.05
#: ... under segments this long (m): they sag L^2 / 8R = 0.64 mm, more than the clearance
SEGMENT = 0.016
EPS_C = 5e-4
PARTICLES = 9


@pytest.fixture(scope="module")
def shoulder():
    return collision_query(*icosphere(radius=RADIUS, subdivisions=5), "shoulder")


def draped_strands(n_strands: int = 6) -> Hair:
    """Coarse strands lying on the sphere along meridians from near its top, one particle every
    :data:`SEGMENT` of chord, the root first."""
    step = 2.0 * np.arcsin(SEGMENT / (2.0 * RADIUS))
    polar = 0.2 + step * np.arange(PARTICLES)
    strands = []
    for azimuth in np.linspace(0.0, 2.0 * np.pi, n_strands, endpoint=False):
        strands.append(RADIUS * np.stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth),
                                          np.cos(polar)], axis=1))
    return Hair.from_strands(strands)


def crossing_count(points, hair, shoulder) -> int:
    return crossing_segments(points, hair.segments, hair.is_root, shoulder).count


def test_coarse_strands_over_a_shoulder_cross_it_with_particle_clearance_only_and_not_after(shoulder):
    hair = draped_strands()
    problem = fine_problem(hair, hair.points, np.ones(hair.n_particles), hair.points)
    particles_only, before = solve_strands(problem, BodyDistance(shoulder), options=SolveOptions(segment_rounds=0))
    free = ~hair.is_root
    assert shoulder.signed_distance(particles_only[free]).distance.min() >= EPS_C - 1e-5
    assert crossing_count(particles_only, hair, shoulder) >= 6 * (PARTICLES - 2)  # all but the segments from the roots
    assert before.segments_crossing == 0 and before.segment_rounds == 0  # not checked

    points, report = solve_strands(problem, BodyDistance(shoulder))
    assert crossing_count(points, hair, shoulder) == 0
    assert report.segments_crossing == crossing_count(particles_only, hair, shoulder)
    assert 1 <= report.segment_rounds <= SolveOptions().segment_rounds and report.segments_left == 0
    assert shoulder.signed_distance(points[free]).distance.min() >= EPS_C - 1e-5
    # the strands keep their shape: lifted by about the sag, not bent; the segment from the root, tangent
    # to the body there, only clears it above the tangent plane: its free end rises by about L^2 / 2R
    lift = np.linalg.norm(points - particles_only, axis=1)
    after_root = hair.offsets[:-1] + 1
    later = np.setdiff1d(np.flatnonzero(free), after_root)
    assert lift[later].max() < SEGMENT**2 / (8 * RADIUS) + 2 * EPS_C
    assert lift[after_root].max() < SEGMENT**2 / (2 * RADIUS) + EPS_C
    angle_change = (mean_segment_angle(points, hair.points, hair.segments)
                    - mean_segment_angle(particles_only, hair.points, hair.segments))
    # the segment from the root turns up by about L / 2R (0.16 rad), the next one by less: 2 of 8 segments
    assert 0.0 < angle_change < 2 * SEGMENT / (2 * RADIUS) / (PARTICLES - 1)


@pytest.mark.parametrize("backend", ["active-set", "osqp"])
def test_coupled_strands_over_a_shoulder_are_cleared_by_either_backend(shoulder, backend):
    hair = draped_strands()
    model = model_of(hair, k=3)
    options = SolveOptions(max_iterations=10)
    before, _ = solve_hairstyle(model, hair.offsets, hair.points, hair.is_root, shoulder, backend=backend,
                                options=SolveOptions(max_iterations=10, segment_rounds=0))
    assert crossing_count(before, hair, shoulder) > 0
    points, report = solve_hairstyle(model, hair.offsets, hair.points, hair.is_root, shoulder, backend=backend,
                                     options=options)
    assert crossing_count(points, hair, shoulder) == 0 and report.segments_left == 0
    assert report.segments_crossing == crossing_count(before, hair, shoulder)
    assert shoulder.signed_distance(points[~hair.is_root]).distance.min() >= EPS_C - 1e-5


def test_windows_reach_a_few_particles_either_side_of_a_segment_merged_within_their_strand():
    offsets = np.array([0, 9, 18])
    windows = segment_windows(offsets, np.array([5, 3, 16, 9]), 2)
    assert windows.tolist() == [[1, 9], [9, 13], [14, 18]]  # no window crosses from one strand into the next


def test_a_window_problem_has_the_whole_problems_energy_in_its_free_particles():
    hair = draped_strands(4)
    rng = np.random.default_rng(2)
    points = hair.points + rng.normal(scale=1e-3, size=hair.points.shape)
    windows = np.array([[2, 7], [12, 18]])  # inside strand 0; strand 1 up to its tip
    weights = EnergyWeights(spacing=10.0)
    fine = fine_problem(hair, hair.points, np.ones(hair.n_particles), hair.points + 1e-3)
    sub, index = window_problem(fine, windows, points)
    np.testing.assert_array_equal(index, np.r_[2:7, 12:18])
    assert sub.n_strands == 2 and not sub.coupled
    assert sub.fixed.tolist() == [True, False, False, False, True] + [True, False, False, False, False, False]

    def energy(problem, at):
        return group_energies(problem, at, weights, np.zeros(problem.n_particles, dtype=np.int64), 1)[0]

    moved = points.copy()
    free = index[~sub.fixed]
    moved[free] += rng.normal(scale=2e-3, size=(len(free), 3))
    np.testing.assert_allclose(energy(sub, moved[index]) - energy(sub, points[index]),
                               energy(fine, moved) - energy(fine, points), rtol=1e-9)
    # coupled: K diagonal, each row the whole residual's with the held particles' share in the features
    coupled = problem_from_shape_model(model_of(hair, k=4), hair.offsets, hair.points, hair.is_root)
    assert coupled.coupled
    sub, index = window_problem(coupled, windows, points)
    assert sp.triu(sub.coupling, 1).nnz == 0 and sp.tril(sub.coupling, -1).nnz == 0
    np.testing.assert_allclose(sub.coupling @ points[index] - sub.features,
                               (coupled.coupling @ points - coupled.features)[index], atol=1e-15)


def test_margins_lift_the_deepest_point_by_its_depth_plus_the_clearance_at_each_ends_lever():
    segments = np.array([[0, 1], [1, 2], [3, 4]])
    fixed = np.array([False, False, False, True, False])
    crossings = SegmentCrossings(rows=np.array([0, 1, 2]), depth=np.array([2e-4, 6e-4, 1e-4]),
                                 deepest_point=np.zeros((3, 3)), deepest_at=np.array([0.5, 0.5, 0.25]),
                                 normal=np.tile([0.0, 0.0, 1.0], (3, 1)))
    distance = np.array([6e-4, 5e-4, 7e-4, 0.0, 5e-4])
    margin = lift_margins(segments, fixed, crossings, distance, EPS_C, np.array([0.0, 0.0, 3e-3, 0.0, 0.0]))
    # both ends free: each rises by depth + eps_c from where it is; particle 1 by the deeper of its two segments
    assert margin[0] == pytest.approx(6e-4 + 2e-4)
    assert margin[1] == pytest.approx(5e-4 + 6e-4)
    assert margin[2] == pytest.approx(3e-3)  # an earlier, larger margin stays
    assert margin[3] == 0.0  # a root takes none
    # the free end of a segment from a root lifts a point a quarter along it by a quarter of its own rise
    assert margin[4] == pytest.approx(5e-4 + 1e-4 / 0.25)
    deep = SegmentCrossings(rows=np.array([0]), depth=np.array([0.02]), deepest_point=np.zeros((1, 3)),
                            deepest_at=np.array([0.5]), normal=np.array([[0.0, 0.0, 1.0]]))
    assert lift_margins(segments, fixed, deep, distance, EPS_C, np.zeros(5))[0] == MAX_MARGIN


def test_a_distance_with_margins_is_the_body_distance_less_each_particles_margin(shoulder):
    points = np.array([[0.0, 0.0, 0.06], [0.0, 0.07, 0.0], [0.08, 0.0, 0.0]])
    plain = BodyDistance(shoulder)
    shifted = plain.with_margin(np.array([1e-3, 0.0, 4e-3]))
    exact = plain(points)[0]
    np.testing.assert_allclose(shifted(points)[0], exact - [1e-3, 0.0, 4e-3])
    np.testing.assert_allclose(shifted(points[[2, 0]], np.array([2, 0]))[0], exact[[2, 0]] - [4e-3, 1e-3])
    assert plain.margin is None  # the original is untouched
    with pytest.raises(ValueError, match="2 points asked about with 3 particles' margins"):
        shifted(points[:2])


def test_a_welds_particles_share_the_largest_margin_of_the_weld():
    hair = Hair.from_strands([np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.01], [0.0, 0.0, 0.01], [0.0, 0.0, 0.02]]),
                              np.array([[0.1, 0.0, 0.0], [0.1, 0.0, 0.01], [0.1, 0.0, 0.02]])])
    problem = fine_problem(hair, hair.points, np.ones(hair.n_particles), hair.points)
    runs = welded_run_ids(problem)
    assert runs.tolist() == [0, 1, 1, 2, 3, 4, 5]  # particles 1 and 2 coincide; a tip never joins the next root
    margin = np.array([0.0, 0.0, 2e-3, 1e-3, 0.0, 5e-4, 0.0])
    assert welded_maximum(margin, runs).tolist() == [0.0, 2e-3, 2e-3, 1e-3, 0.0, 5e-4, 0.0]
