"""Tests for solver/wrap/nricp.py: the stiff-to-soft non-rigid ICP loop."""

from __future__ import annotations

import numpy as np

from hairport.solver.mesh.shells import edge_table
from hairport.solver.wrap.landmarks import Landmarks
from hairport.solver.wrap.nricp import Normalisation, fit
from hairport.solver.wrap.options import WrapOptions
from hairport.solver.wrap.surface import TargetSurface
from tests.solver.wrap.conftest import sphere


def test_normalisation_round_trip():
    points = np.random.default_rng(0).normal(size=(50, 3)) * 0.1 + [0.0, 1.6, 0.0]
    frame = Normalisation.of(points)
    normal = frame.forward(points)
    np.testing.assert_allclose(normal.mean(axis=0), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.sqrt((normal ** 2).sum(axis=1).mean()), 1.0)
    np.testing.assert_allclose(frame.back(normal), points, atol=1e-15)


def test_a_sphere_is_fitted_onto_an_ellipsoid_of_another_tessellation():
    source, faces = sphere(0.1, 3)
    target, target_faces = sphere(1.0, 4)
    target = target * [0.12, 0.09, 0.1]  # an ellipsoid, more finely tessellated
    positions, log = fit(source, faces, edge_table(faces).ends, TargetSurface(target, target_faces),
                         Landmarks.none(), WrapOptions())
    _, distance, _, _ = TargetSurface(target, target_faces).closest(positions)
    assert distance.mean() < 2e-4 and distance.max() < 1e-3
    # the ellipsoid is the sphere stretched: the stiff steps find that map, the soft ones keep it
    stretched = source * [1.2, 0.9, 1.0]
    assert np.linalg.norm(positions - stretched, axis=1).mean() < 1e-3
    assert log.iterations >= len(WrapOptions().stiffness)
    assert 1 <= log.factorisations <= log.iterations
    assert log.accepted_share[-1] > 0.99


def test_a_landmark_pulls_its_point_in_the_stiff_steps():
    source, faces = sphere(0.1, 3)
    surface = TargetSurface(source, faces)
    top = int(np.argmax(source[:, 1]))
    # the top of the sphere should meet a point 3 cm along the surface towards +Z
    angle = 0.3
    goal = 0.1 * np.array([0.0, np.cos(angle), np.sin(angle)])
    landmarks = Landmarks(("top",), np.array([[top, top, top]]), np.array([[1.0, 0.0, 0.0]]), goal[None])
    options = WrapOptions(landmark_weights=(1.0,))
    positions, _ = fit(source, faces, edge_table(faces).ends, surface, landmarks, options)
    free, _ = fit(source, faces, edge_table(faces).ends, surface, Landmarks.none(), options)
    assert np.linalg.norm(positions[top] - goal) < 0.005
    assert np.linalg.norm(free[top] - source[top]) < 1e-3
