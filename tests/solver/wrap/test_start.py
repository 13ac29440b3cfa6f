"""Tests for solver/wrap/start.py: the similarity that starts the wrap."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from hairport.solver.body.head_frame import mesh_head_frame
from hairport.solver.model.character import Character
from hairport.solver.wrap.options import WrapOptions
from hairport.solver.wrap.region import region_mesh
from hairport.solver.wrap.start import (
    IDENTITY,
    Similarity,
    fit_similarity,
    head_similarity,
    refine_similarity,
    start_similarity,
)
from hairport.solver.wrap.surface import TargetSurface


def _known():
    return Similarity(1.3, Rotation.from_euler("xyz", [5, -10, 3], degrees=True).as_matrix(), np.array([0.1, -0.2, 0.05]))


def test_fit_similarity_recovers_a_known_one():
    points = np.random.default_rng(0).normal(size=(40, 3))
    known = _known()
    fitted = fit_similarity(points, known.apply(points))
    assert abs(fitted.scale - 1.3) < 1e-12
    np.testing.assert_allclose(fitted.rotation, known.rotation, atol=1e-12)
    np.testing.assert_allclose(fitted.translation, known.translation, atol=1e-12)
    assert abs(known.angle_deg - np.degrees(Rotation.from_matrix(known.rotation).magnitude())) < 1e-9
    # zero weights ignore pairs; rotate=False fits scale and translation only
    moved = known.apply(points)
    moved[:5] += 10.0
    weights = np.r_[np.zeros(5), np.ones(35)]
    assert abs(fit_similarity(points, moved, weights).scale - 1.3) < 1e-12
    shifted = fit_similarity(points, 2.0 * points + 1.0, rotate=False)
    assert abs(shifted.scale - 2.0) < 1e-12 and np.allclose(shifted.rotation, np.eye(3))
    np.testing.assert_allclose(shifted.translation, 1.0, atol=1e-12)


def test_similarities_compose():
    known, points = _known(), np.random.default_rng(1).normal(size=(5, 3))
    np.testing.assert_allclose(known.then(known).apply(points), known.apply(known.apply(points)), atol=1e-12)
    np.testing.assert_allclose(IDENTITY.apply(points), points)


def test_head_similarity_puts_one_head_frame_on_the_other(toys):
    source, target, _ = toys
    frames = mesh_head_frame(Character(source.vertices, source.faces)), mesh_head_frame(Character(target.vertices, target.faces))
    start = head_similarity(*frames)
    np.testing.assert_allclose(start.apply(frames[0].origin), frames[1].origin, atol=1e-12)
    assert 1.0 < start.scale < 1.15  # the second toy's head is larger
    # a head scaled and moved as a whole: the similarity is found exactly
    moved = Character(1.5 * source.vertices + [0.0, 0.3, 0.1], source.faces)
    start = head_similarity(frames[0], mesh_head_frame(moved))
    assert abs(start.scale - 1.5) < 1e-9
    np.testing.assert_allclose(start.apply(source.vertices), moved.vertices, atol=1e-9)


def test_refine_and_start_recover_a_displaced_head(toys):
    source = toys[0]
    frame = mesh_head_frame(Character(source.vertices, source.faces))
    ids, triangles, _ = region_mesh(source.faces, frame.head_vertices)
    surface = TargetSurface(source.vertices, source.faces)
    off = Similarity(1.03, Rotation.from_euler("y", 3, degrees=True).as_matrix(), np.array([0.01, -0.008, 0.005]))
    refined = refine_similarity(off, source.vertices[ids], triangles, surface, 0.05, 0.5, 50, 1e-7)
    before = np.linalg.norm(off.apply(source.vertices[ids]) - source.vertices[ids], axis=1)
    after = np.linalg.norm(refined.apply(source.vertices[ids]) - source.vertices[ids], axis=1)
    # point-to-point ICP slides slowly along a near-symmetric head: most of the way, not all of it
    assert after.mean() < 0.1 * before.mean() and after.mean() < 5e-3
    # start_similarity: landmarks when three or more, refined on the head either way
    pairs = {str(i): (source.vertices[i], off.apply(source.vertices[i])) for i in ids[::50]}
    target = TargetSurface(off.apply(source.vertices), source.faces)
    frames = (frame, mesh_head_frame(Character(off.apply(source.vertices), source.faces)))
    for landmarks, bound in ((pairs, 1e-6), ({}, 5e-3)):
        start = start_similarity(source.vertices, (ids, triangles), frames, target, landmarks, WrapOptions())
        assert np.linalg.norm(start.apply(source.vertices[ids]) - off.apply(source.vertices[ids]), axis=1).mean() < bound
