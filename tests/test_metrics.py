"""Metrics of DESIGN.md section 4 on hand-solvable cases."""

import numpy as np
import trimesh

from hairport.solver.mesh.query import MeshQuery
from hairport.solver.metrics import mean_particle_distance, mean_segment_angle, penetration, segment_angles


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
