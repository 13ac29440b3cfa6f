"""Eq. 2's anchor-bone search (solver/transfer/bone_rays.py): the pruned search equals casting every ray."""

import numpy as np
import pytest

from hairport.solver.mesh.query import MeshQuery
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import PRESETS, build_character
from hairport.solver.transfer import anchors as anchoring
from hairport.solver.transfer.anchors import ANCHOR_SIGMA, compute_anchors
from hairport.solver.transfer.bone_rays import (
    anchor_by_bones,
    anchor_by_bones_exhaustive,
    score_bounds,
    score_bounds_reference,
)
from tests.solver.hair_shapes import outward_strands, sphere_character


@pytest.fixture(scope="module")
def long_groom():
    """The MakeHuman source with a long groom reaching the shoulders: every hair bone gets particles."""
    source = build_character(PRESETS["average-female"])
    hair = generate_groom(source, "long", 300, 30, seed=1)
    query = MeshQuery(source.vertices, source.faces)
    return source, hair, query, anchoring._source_bone_rays(source, query)


def _search(search, rays, query, hair):
    n = hair.n_particles
    best = {"bone": np.full(n, -1), "face": np.full(n, -1), "barycentric": np.zeros((n, 3)), "eta": np.zeros(n)}
    distance = query.signed_distance(hair.points).distance
    reached = search(rays, query, hair.points, hair.is_root, distance, ANCHOR_SIGMA, best)
    return reached, best


def test_the_pruned_search_finds_the_exhaustive_search_s_anchors_bit_for_bit(long_groom):
    source, hair, query, rays = long_groom
    reached, best = _search(anchor_by_bones, rays, query, hair)
    reference_reached, reference = _search(anchor_by_bones_exhaustive, rays, query, hair)
    np.testing.assert_array_equal(reached, reference_reached)
    for name in best:
        np.testing.assert_array_equal(best[name], reference[name], err_msg=name)
    # a groom that exercises the choice: several bones win, a few particles fall back
    won = np.unique(best["bone"][reached])
    assert len(won) >= 4 and reached.sum() > 0.95 * (~hair.is_root).sum()


def test_the_bounds_never_exceed_a_bone_s_score_and_the_kernel_matches_numpy(long_groom):
    source, hair, query, rays = long_groom
    free = np.flatnonzero(~hair.is_root)
    points = hair.points[free]
    distance = query.signed_distance(points).distance
    reach = 2.0 * np.abs(distance) + 0.01
    bound = score_bounds(rays, points, np.abs(distance), reach, ANCHOR_SIGMA)
    reference = score_bounds_reference(rays, points, np.abs(distance), reach, ANCHOR_SIGMA)
    np.testing.assert_array_equal(np.isinf(bound), np.isinf(reference))
    finite = np.isfinite(bound)
    np.testing.assert_allclose(bound[finite], reference[finite], rtol=1e-12, atol=0)
    # each bone's actual score, by the exhaustive search restricted to that bone
    for j in range(len(rays.bones)):
        single = type(rays)(rays.bones[j : j + 1], rays.valid[:, j : j + 1], rays.face_normals,
                            rays.inner_heads[j : j + 1], rays.inner_tails[j : j + 1], rays.axes[j : j + 1],
                            rays.region_lower[j : j + 1], rays.region_upper[j : j + 1])
        n = len(points)
        best = {"bone": np.full(n, -1), "face": np.full(n, -1), "barycentric": np.zeros((n, 3)), "eta": np.zeros(n)}
        scored = anchor_by_bones_exhaustive(single, query, points, np.zeros(n, bool), distance, ANCHOR_SIGMA, best)
        score = np.abs(best["eta"][scored]) * np.exp(ANCHOR_SIGMA * _cosines(rays, j, points[scored]) ** 2)
        assert (bound[scored, j] <= score).all()
    assert np.isinf(bound).mean() > 0.2  # the regions' boxes rule bones out without a ray


def _cosines(rays, j, points):
    from hairport.solver.transfer.bone_rays import _rays_of_bone

    return _rays_of_bone(rays, j, points)[3]


def test_anchors_do_not_depend_on_the_chunk_size(long_groom):
    source, hair, query, _ = long_groom
    whole = compute_anchors(source, hair.points, hair.is_root, query)
    chunked = compute_anchors(source, hair.points, hair.is_root, query, chunk=997)
    for name in ("bone", "face", "barycentric", "eta", "frame_offset", "fallback"):
        np.testing.assert_array_equal(getattr(chunked, name), getattr(whole, name), err_msg=name)
    assert whole.fallback.any()  # the chunks also carry fallback rows


def test_pruned_and_exhaustive_agree_on_the_sphere_head():
    source = sphere_character()
    hair = outward_strands(source, n_strands=60, n_points=10)
    query = MeshQuery(source.vertices, source.faces)
    rays = anchoring._source_bone_rays(source, query)
    reached, best = _search(anchor_by_bones, rays, query, hair)
    reference_reached, reference = _search(anchor_by_bones_exhaustive, rays, query, hair)
    np.testing.assert_array_equal(reached, reference_reached)
    assert reached[~hair.is_root].all()
    for name in best:
        np.testing.assert_array_equal(best[name], reference[name], err_msg=name)
