"""Fixtures of the wrap tests: small meshes, the toy bodies remeshed, and MakeHuman targets (or a skip)."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from hairport.solver.synthetic.remesh import remesh
from hairport.solver.synthetic.toy import toy_character
from tests.solver.synthetic.toy_fixtures import PRESET_B


def sphere(radius: float = 0.1, subdivisions: int = 3, centre=(0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) of an icosphere, counter-clockwise seen from outside."""
    mesh = trimesh.creation.icosphere(subdivisions, radius)
    return np.asarray(mesh.vertices) + np.asarray(centre), np.asarray(mesh.faces, dtype=np.int64)


def grid(n: int = 11, size: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) of a flat square in the XY plane (normals +Z), ``n`` x ``n`` vertices."""
    x, y = np.meshgrid(np.linspace(0.0, size, n), np.linspace(0.0, size, n))
    vertices = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    ids = np.arange(n * n).reshape(n, n)
    a, b, c, d = ids[:-1, :-1].ravel(), ids[:-1, 1:].ravel(), ids[1:, :-1].ravel(), ids[1:, 1:].ravel()
    faces = np.concatenate([np.stack([a, b, d], axis=1), np.stack([a, d, c], axis=1)])
    return vertices, faces.astype(np.int64)


@pytest.fixture(scope="session")
def toys():
    """(source toy, target toy with another head and neck, the target remeshed to 3,000 vertices)."""
    source, target = toy_character(), toy_character(**PRESET_B, name="toy-b")
    return source, target, remesh(target.vertices, target.faces, 3000, seed=1)
