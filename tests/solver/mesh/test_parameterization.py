"""Disk parameterizations (harmonic, LSCM, ARAP) of flat disks and their injectivity checks."""

import numpy as np
import pytest
from scipy.spatial import Delaunay

from hairport.solver.mesh.areas import signed_areas
from hairport.solver.mesh.parameterization import (
    PARAMETERIZATIONS,
    _segments_cross,
    check_injective,
    check_parameterization,
    parameterize,
)
from hairport.solver.mesh.topology import boundary_loops
from hairport.solver.model.errors import InputError


def flat_disk(rotation: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A planar disk of radius 5 cm in 3D: 40 boundary points equally spaced on the circle,
    jittered interior points, Delaunay triangles (counter-clockwise in the disk's plane)."""
    rng = np.random.default_rng(3)
    angle = 2 * np.pi * np.arange(40) / 40
    boundary = 0.05 * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    inner = []
    for r, count in ((0.035, 28), (0.02, 16), (0.008, 6)):
        a = 2 * np.pi * (np.arange(count) + rng.uniform(-0.3, 0.3, count)) / count
        inner.append(r * rng.uniform(0.9, 1.1, (count, 1)) * np.stack([np.cos(a), np.sin(a)], axis=1))
    xy = np.concatenate([boundary] + inner + [np.zeros((1, 2))])
    triangles = Delaunay(xy).simplices.astype(np.int64)
    area = signed_areas(xy, triangles)
    triangles[area < 0] = triangles[area < 0][:, ::-1]
    points = np.column_stack([xy, np.zeros(len(xy))]) @ rotation.T + np.array([0.3, 1.6, -0.2])
    return xy, points, triangles


def test_harmonic_map_of_a_flat_disk_is_a_similarity():
    c, s = np.cos(0.7), np.sin(0.7)
    rotation = np.array([[1, 0, 0], [0, c, -s], [0, s, c]]) @ np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    xy, points, triangles = flat_disk(rotation)
    uv = parameterize(points, triangles, "harmonic")
    # fit uv = a z + b over complex numbers (rotation + uniform scale + translation)
    z, w = xy[:, 0] + 1j * xy[:, 1], uv[:, 0] + 1j * uv[:, 1]
    design = np.column_stack([z, np.ones_like(z)])
    (a, b), *_ = np.linalg.lstsq(design, w, rcond=None)
    assert np.abs(design @ np.array([a, b]) - w).max() < 1e-12
    assert abs(abs(a) - 1 / 0.05) < 1e-9 and abs(b) < 1e-12
    # the free-boundary maps of a flat disk are similarities too (conformal and rigid)
    for method in ("lscm", "arap"):
        uv = parameterize(points, triangles, method)
        w = uv[:, 0] + 1j * uv[:, 1]
        (a, b), *_ = np.linalg.lstsq(design, w, rcond=None)
        assert np.abs(design @ np.array([a, b]) - w).max() < 1e-6, method


def test_not_a_disk_is_refused():
    xy, points, triangles = flat_disk(np.eye(3))
    # an annulus: drop the triangles around the centre
    centre = len(points) - 1
    annulus = triangles[~(triangles == centre).any(axis=1)]
    used = np.unique(annulus)
    renumber = np.full(len(points), -1)
    renumber[used] = np.arange(len(used))
    with pytest.raises(InputError, match="not a disk: 2 boundary loops"):
        parameterize(points[used], renumber[annulus], "harmonic")
    # two separate triangles
    two = np.array([[0, 1, 2], [3, 4, 5]])
    with pytest.raises(InputError, match="not a disk"):
        parameterize(np.random.default_rng(0).random((6, 3)), two, "lscm")
    # a closed surface has no boundary
    tetra = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])
    with pytest.raises(InputError, match="0 boundary loops"):
        parameterize(np.eye(4, 3), tetra, "arap")


def test_bad_arguments_are_refused():
    xy, points, triangles = flat_disk(np.eye(3))
    with pytest.raises(InputError, match="unknown parameterization"):
        parameterize(points, triangles, "tutte")
    with pytest.raises(InputError, match="used by no triangle"):
        parameterize(np.vstack([points, [[9.0, 9, 9]]]), triangles)
    with pytest.raises(InputError, match="out of range"):
        parameterize(points, triangles + 1)


def test_flipped_maps_are_detected():
    xy, points, triangles = flat_disk(np.eye(3))
    loop = boundary_loops(triangles)[0]
    check_injective(xy, triangles, loop)
    folded = xy.copy()
    folded[len(xy) - 1] = [0.045, 0.0]  # drag the centre vertex over its neighbours
    with pytest.raises(InputError, match="flips or collapses"):
        check_injective(folded, triangles, loop, "harmonic")
    crossed = xy.copy()
    crossed[loop[0]] = [-0.06, 0.0]  # boundary across the disk: flips and crossings
    with pytest.raises(InputError, match="flips|crosses"):
        check_injective(crossed, triangles, loop)


def test_boundary_crossings():
    square = np.array([[0.0, 0], [1, 0], [1, 1], [0, 1]])
    bowtie = square[[0, 1, 3, 2]]
    assert not _segments_cross(square)
    assert _segments_cross(bowtie)


def test_check_parameterization():
    for method in PARAMETERIZATIONS:
        check_parameterization(method)
    with pytest.raises(InputError, match="unknown parameterization 'tutte'; expected one of harmonic, lscm, arap") as caught:
        check_parameterization("tutte")
    assert caught.value.code == "bad_option"
