"""Metrics of DESIGN.md section 4 (solver/metrics.py) on hand-solvable cases."""

import numpy as np
import pytest
import trimesh

from hairport.solver.adaptation.problem.energies import EnergyWeights, energy_terms
from hairport.solver.adaptation.source.neighbours import knn_other_strands
from hairport.solver.mesh.polyline import rest_lengths
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.metrics import (
    bend_errors,
    hairstyle_metrics,
    interstrand_error,
    interstrand_residual,
    interstrand_residual_norms,
    length_ratios,
    mean_particle_distance,
    mean_segment_angle,
    penetration,
    root_errors,
    segment_angles,
    segment_figures,
)
from tests.solver.hair_shapes import model_of, parallel_strands


def test_mean_particle_distance():
    a = np.zeros((4, 3))
    b = np.array([[1.0, 0, 0], [0, 2.0, 0], [0, 0, 3.0], [0, 0, 0]])
    assert mean_particle_distance(a, b) == 1.5


def test_segment_angles_of_a_known_turn_and_of_tiny_turns():
    segments = np.array([[0, 1]])
    a = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    b = np.array([[0.0, 0, 0], [np.cos(0.3), np.sin(0.3), 0]])
    assert abs(segment_angles(a, b, segments)[0] - 0.3) < 1e-15
    tiny = np.array([[0.0, 0, 0], [1.0, 1e-9, 0]])
    assert abs(mean_segment_angle(a, tiny, segments) - 1e-9) < 1e-20  # atan2 keeps tiny angles


def test_penetration_counts_inside_and_short_of_clearance():
    sphere = trimesh.creation.icosphere(5, radius=1.0)
    query = MeshQuery(sphere.vertices, sphere.faces)
    # radial points over a face centre, at known signed distances from the polyhedron
    centre = sphere.triangles_center[0]
    normal = sphere.face_normals[0]
    offsets = np.array([-1e-3, 4e-4, 5e-4 - 1e-8, 1e-3])  # inside, short, short within tolerance, clear
    points = centre + offsets[:, None] * normal
    stats = penetration(points, np.zeros(4, dtype=bool), query, eps_c=5e-4)
    np.testing.assert_allclose(stats["distance"], offsets, atol=1e-12)
    assert stats["inside"] == 1
    assert stats["below_clearance"] == 2
    assert abs(stats["min_distance"] + 1e-3) < 1e-12


def test_root_errors_to_targets_and_to_the_surface():
    sphere = trimesh.creation.icosphere(3, radius=1.0)
    query = MeshQuery(sphere.vertices, sphere.faces)
    centres, normals = sphere.triangles_center[:2], sphere.face_normals[:2]
    roots = centres + np.array([[1e-3], [0.0]]) * normals  # 1 mm off the surface, and on it
    targets = roots + [[0.0, 0.0, 3e-3], [4e-3, 0.0, 0.0]]
    errors = root_errors(roots, targets, query)
    assert list(errors) == ["root_to_target_max", "root_to_target_mean", "root_to_surface_max", "root_to_surface_mean"]
    np.testing.assert_allclose([errors["root_to_target_max"], errors["root_to_target_mean"]], [4e-3, 3.5e-3], rtol=1e-12)
    np.testing.assert_allclose([errors["root_to_surface_max"], errors["root_to_surface_mean"]], [1e-3, 5e-4], atol=1e-15)
    assert root_errors(np.zeros((0, 3)), np.zeros((0, 3)), query) == dict.fromkeys(errors, 0.0)


def test_interstrand_error_and_all_metrics_of_a_moved_hairstyle():
    hair = parallel_strands(n_strands=3, n_points=5)
    model = model_of(hair, k=2)
    nb = knn_other_strands(hair.points, hair.strand_of, 2)
    shifted = hair.points.copy()
    shifted[hair.strand_of == 1] += [0.0, 0.0, 0.002]  # the middle strand 2 mm off its neighbours
    assert interstrand_error(nb, hair.points + 0.5, hair.points) < 1e-15  # Eq. 10 ignores translations
    # the residual without K equals the sparse operator's K p - L-bar
    np.testing.assert_allclose(interstrand_residual(nb, shifted, hair.points), model.K @ shifted - model.source_features,
                               rtol=0, atol=1e-17)
    expected = np.mean(np.linalg.norm(model.K @ shifted - model.source_features, axis=1))
    assert interstrand_error(nb, shifted, hair.points) == pytest.approx(expected, rel=1e-13)
    assert expected > 1e-3

    body = trimesh.creation.icosphere(2, radius=0.005)  # a small ball far below the strands
    query = MeshQuery(np.asarray(body.vertices) + [0.0, -0.5, 0.0], body.faces)
    roots = hair.points[hair.roots]
    metrics = hairstyle_metrics(shifted, hair, hair.points, roots, nb, query, eps_c=5e-4)
    n = hair.n_particles
    assert metrics["particles"] == n and metrics["penetrating_particles"] == metrics["particles_below_clearance"] == 0
    assert metrics["mean_segment_angle_rad"] == metrics["max_segment_angle_rad"] == 0.0  # a translated strand
    assert metrics["mean_bend_error_rad"] == metrics["max_bend_error_rad"] == 0.0
    assert metrics["mean_distance_to_initial_m"] == pytest.approx(0.002 * 5 / n, rel=1e-12)
    assert metrics["interstrand_error_m"] == pytest.approx(expected, rel=1e-13)
    terms = energy_terms(model, shifted, hair.points)
    assert metrics["energy_inter_strand_per_particle"] == pytest.approx(terms.inter_strand / n, rel=1e-13)
    assert metrics["energy_hair_body_per_particle"] == pytest.approx(5 * 0.002**2 / n, rel=1e-12)
    assert metrics["energy_total_per_particle"] == pytest.approx(terms.total(EnergyWeights()) / n, rel=1e-13)
    assert metrics["root_to_target_max"] == pytest.approx(0.002, rel=1e-12)  # the middle strand's root moved too
    assert metrics["root_to_target_mean"] == pytest.approx(0.002 / 3, rel=1e-12)
    assert metrics["min_signed_distance_m"] == pytest.approx(0.5 - 0.02 - 0.005, abs=1e-9)  # tip over the ball's pole
    assert metrics["segment_length_ratio"] == metrics["strand_length_ratio"] == {"p5": 1.0, "p50": 1.0, "p95": 1.0}


@pytest.mark.parametrize("chunk", [1, 7, 1 << 18])
def test_segment_figures_equal_the_per_segment_angles_and_eq7_in_any_block_size(chunk):
    hair = parallel_strands(n_strands=4, n_points=9)
    rng = np.random.default_rng(2)
    bent = hair.points + rng.normal(scale=1e-3, size=hair.points.shape)
    figures = segment_figures(bent, hair.points, hair.offsets, chunk=chunk)
    angles = segment_angles(bent, hair.points, hair.segments)
    assert figures.count == len(hair.segments) == 4 * 8
    assert figures.angle_sum == pytest.approx(angles.sum(), rel=1e-13) and figures.angle_max == angles.max() > 0.05
    assert figures.strand_shape == pytest.approx(energy_terms(model_of(hair, k=2), bent, hair.points).strand_shape,
                                                 rel=1e-13)


@pytest.mark.parametrize("chunk", [1, 3, 1 << 18])
def test_bend_errors_see_a_kink_and_not_a_turned_strand(chunk):
    straight = np.array([[0.0, 0, 0], [0, 1, 0], [0, 2, 0], [0, 3, 0], [5, 0, 0], [5, 1, 0], [5, 2, 0]])
    offsets = np.array([0, 4, 7])
    turned = straight.copy()
    turned[4:] = [[5, 0, 0], [6, 0, 0], [7, 0, 0]]  # the second strand turned as a whole: no bend changed
    assert bend_errors(turned, straight, offsets, chunk) == (0.0, 0.0)
    kinked = straight.copy()
    kinked[2:4] = [[1, 1, 0], [2, 1, 0]]  # a right angle at particle 1, on straight at particle 2
    mean, largest = bend_errors(kinked, straight, offsets, chunk)
    assert largest == pytest.approx(np.pi / 2) and mean == pytest.approx(np.pi / 2 / 3)  # 3 interior particles
    assert bend_errors(straight[:2], straight[:2], np.array([0, 2]), chunk) == (0.0, 0.0)  # no interior particle


def test_the_compiled_residual_norms_equal_the_numpy_residual_s():
    hair = parallel_strands(n_strands=5, n_points=7)
    nb = knn_other_strands(hair.points, hair.strand_of, 3)
    moved = hair.points + np.random.default_rng(1).normal(scale=1e-3, size=hair.points.shape)
    reference = np.linalg.norm(interstrand_residual(nb, moved, hair.points), axis=1)
    np.testing.assert_allclose(interstrand_residual_norms(nb, moved, hair.points), reference, rtol=1e-14, atol=1e-18)
    assert reference.min() > 0


@pytest.mark.parametrize("chunk", [1, 2, 1 << 18])
def test_length_ratios_of_segments_within_their_strand_and_of_strands(chunk):
    """Strand 1 doubles evenly; strand 2 keeps its length but bunches (0.5 then 1.25); a one-point strand has
    no segment; a segment of zero source length is left out."""
    offsets = np.array([0, 3, 6, 7, 9])
    source = np.array([[0, 0, 0], [0, 1, 0], [0, 2, 0], [1, 0, 0], [1, 1, 0], [1, 3, 0], [5, 5, 5],
                       [2, 0, 0], [2, 0, 0]], float)
    points = source.copy()
    points[1:3] *= [1, 2, 1]
    points[4] = [1, 0.5, 0]
    ratios = length_ratios(points, source, offsets, chunk=chunk)
    assert ratios["segment_length_ratio"]["p50"] == pytest.approx(np.percentile([2, 2, 0.5, 1.25], 50))
    assert ratios["segment_length_ratio_in_strand"] == pytest.approx(
        {f"p{p}": np.percentile([1, 1, 0.5, 1.25], p) for p in (5, 50, 95)}, rel=1e-6)
    assert ratios["strand_length_ratio"] == pytest.approx({"p5": 1.05, "p50": 1.5, "p95": 1.95})
    scaled = length_ratios(source * 1.1, source, offsets, chunk=chunk)  # a body 10 % larger: even growth
    assert scaled["segment_length_ratio_in_strand"] == pytest.approx({"p5": 1.0, "p50": 1.0, "p95": 1.0}, rel=1e-6)
    assert scaled["strand_length_ratio"] == pytest.approx({"p5": 1.1, "p50": 1.1, "p95": 1.1})


def test_with_the_spacing_term_on_the_energy_counts_it():
    hair = parallel_strands(n_strands=3, n_points=5)
    nb = knn_other_strands(hair.points, hair.strand_of, 2)
    body = trimesh.creation.icosphere(2, radius=0.005)
    query = MeshQuery(np.asarray(body.vertices) + [0.0, -0.5, 0.0], body.faces)
    stretched = hair.points.copy()
    stretched[hair.offsets[0] + 1:hair.offsets[1]] *= [1.0, 1.5, 1.0]  # the first strand's segments 1.5x along y
    stretched[hair.offsets[0] + 1:hair.offsets[1], 1] -= 0.5 * hair.points[hair.offsets[0], 1]
    roots = hair.points[hair.roots]
    plain = hairstyle_metrics(stretched, hair, hair.points, roots, nb, query, eps_c=5e-4)
    assert "energy_spacing_per_particle" not in plain
    weights = EnergyWeights(spacing=2.0)
    spaced = hairstyle_metrics(stretched, hair, hair.points, roots, nb, query, eps_c=5e-4, weights=weights)
    rest = rest_lengths(hair.points, hair.points, hair.offsets)
    starts = np.flatnonzero(rest > 0)
    length = np.linalg.norm(stretched[starts + 1] - stretched[starts], axis=1)
    expected = np.sum((length / rest[starts] - 1.0) ** 2) / hair.n_particles
    assert expected > 0.05
    assert spaced["energy_spacing_per_particle"] == pytest.approx(expected, rel=1e-12)
    assert spaced["energy_total_per_particle"] == pytest.approx(plain["energy_total_per_particle"] + 2.0 * expected,
                                                                rel=1e-12)


def test_the_hair_body_relation_change_is_how_far_each_offset_to_the_body_moved():
    from hairport.solver.mesh.query import MeshQuery
    from hairport.solver.metrics import hair_body_relation_change
    from tests.solver.mesh.meshes import icosphere

    vertices, faces = icosphere(radius=0.1, subdivisions=4)
    source_body, body = MeshQuery(vertices, faces), MeshQuery(1.1 * vertices, faces)
    rng = np.random.default_rng(2)
    directions = rng.normal(size=(200, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    source = 0.12 * directions  # 2 cm off the source sphere (less its facets' sag, the same on both)
    is_root = np.zeros(200, dtype=bool)
    is_root[:10] = True
    kept = 0.13 * directions  # 2 cm off the larger sphere: the same relation
    assert hair_body_relation_change(kept, source, is_root, body, source_body) < 2e-4
    farther = 0.135 * directions  # 5 mm farther out
    assert hair_body_relation_change(farther, source, is_root, body, source_body) == pytest.approx(5e-3, abs=3e-4)
    moved = farther.copy()
    moved[:10] += 1.0  # roots are not measured
    assert hair_body_relation_change(moved, source, is_root, body, source_body) == pytest.approx(
        hair_body_relation_change(farther, source, is_root, body, source_body))
