"""Initial transfer: anchoring (Eq. 2-3) and adaptive smoothing (Eq. 4-6)."""

import numpy as np
import scipy.sparse as sp
import trimesh

from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.character import Character, Skeleton
from hairport.solver.model.hair import Hair
from hairport.solver.transfer.anchors import compute_anchors, place_anchors
from hairport.solver.transfer.smoothing import smooth_strands, strand_laplacian


def sphere_character(scale=(1.0, 1.0, 1.0), shift=(0.0, 0.0, 0.0)):
    mesh = trimesh.creation.icosphere(3, radius=0.1)
    m = np.asarray(scale)
    t = np.asarray(shift)
    skeleton = Skeleton(("neck_01", "head"), [-1, 0], [[0, -0.12, 0], [0, -0.04, 0]], [[0, -0.04, 0], [0, 0.07, 0]])
    skeleton = Skeleton(skeleton.names, skeleton.parents, skeleton.heads * m + t, skeleton.tails * m + t)
    weights = np.zeros((len(mesh.vertices), 2))
    weights[:, 1] = 1.0
    return Character(np.asarray(mesh.vertices) * m + t, mesh.faces, skeleton, sp.csr_matrix(weights), "sphere")


def outward_strands(character, n_strands=40, n_points=8, seed=0):
    rng = np.random.default_rng(seed)
    direction = rng.normal(size=(n_strands, 3))
    direction[:, 1] = np.abs(direction[:, 1]) + 0.2
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    sd = MeshQuery(character.vertices, character.faces).signed_distance(direction * 0.3)
    strands = [sd.closest[s] + np.outer(np.arange(n_points) * 0.004, sd.normal[s] + [0, -0.3, 0])
               for s in range(n_strands)]
    return Hair.from_strands(strands)


def test_reflexive_anchoring_reproduces_particles():
    source = sphere_character()
    hair = outward_strands(source)
    anchors = compute_anchors(source, hair.points, hair.is_root)
    assert not anchors.fallback.any()
    np.testing.assert_allclose(place_anchors(anchors, source), hair.points, atol=1e-12)


def test_anchoring_follows_a_translation_and_uniform_scale_about_the_bone():
    source = sphere_character()
    hair = outward_strands(source)
    anchors = compute_anchors(source, hair.points, hair.is_root)
    moved = sphere_character(shift=(0.05, 0.02, -0.01))
    np.testing.assert_allclose(place_anchors(anchors, moved), hair.points + [0.05, 0.02, -0.01], atol=1e-12)
    # a uniformly scaled head: hit points scale, the distance beyond the surface is kept
    scaled = sphere_character(scale=(1.2, 1.2, 1.2))
    placed = place_anchors(anchors, scaled)
    surface = MeshQuery(scaled.vertices, scaled.faces).signed_distance(placed[~hair.is_root]).distance
    original = MeshQuery(source.vertices, source.faces).signed_distance(hair.points[~hair.is_root]).distance
    np.testing.assert_allclose(surface, original, atol=2e-3)


def test_roots_land_on_the_target_surface():
    source = sphere_character()
    hair = outward_strands(source)
    anchors = compute_anchors(source, hair.points, hair.is_root)
    target = sphere_character(scale=(1.15, 0.9, 1.05))
    roots = place_anchors(anchors, target)[hair.roots]
    assert np.abs(MeshQuery(target.vertices, target.faces).signed_distance(roots).distance).max() < 1e-12


def test_strand_laplacian_of_a_straight_line_is_zero_and_of_a_corner_is_the_turn():
    points = np.stack([np.zeros(5), -0.01 * np.arange(5), np.zeros(5)], axis=1)
    L = strand_laplacian(points, np.array([0, 5]))
    np.testing.assert_allclose(L @ points, 0.0, atol=1e-15)
    assert np.diff(L.indptr)[[0, 4]].tolist() == [0, 0]  # no rows for root and tip
    corner = np.array([[0.0, 0, 0], [0.0, -0.01, 0], [0.02, -0.01, 0]])
    # unit directions (0,-1,0) then (1,0,0): the Laplacian is their difference
    np.testing.assert_allclose((strand_laplacian(corner, np.array([0, 3])) @ corner)[1], [1.0, 1.0, 0.0])


def test_smoothing_leaves_a_smooth_transfer_untouched():
    source = sphere_character()
    hair = outward_strands(source)
    smoothed, unsmooth = smooth_strands(hair.points + 0.01, hair.points, hair.offsets)
    assert not unsmooth.any()
    np.testing.assert_array_equal(smoothed, hair.points + 0.01)


def test_smoothing_removes_a_staircase_step():
    n = 12
    source = np.stack([np.zeros(n), -0.005 * np.arange(n), np.zeros(n)], axis=1)
    stair = source.copy()
    stair[6:, 0] += 0.004  # a 4 mm jog between particle 5 and 6
    offsets = np.array([0, n])
    L = strand_laplacian(source, offsets)
    smoothed, unsmooth = smooth_strands(stair, source, offsets)
    assert unsmooth[5] and unsmooth[6]
    before = np.linalg.norm(L @ stair - L @ source, axis=1).max()
    after = np.linalg.norm(L @ smoothed - L @ source, axis=1).max()
    assert before > 0.3 and after <= 0.3
    assert smoothed[0].tolist() == stair[0].tolist()  # the root is Dirichlet
