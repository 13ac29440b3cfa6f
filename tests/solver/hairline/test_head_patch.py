"""The head patch around the scalp: a disk of head faces, parameterizable by every method."""

import numpy as np
import pytest

from hairport.solver.hairline.head_patch import DEFAULT_MARGIN_RINGS, head_patch
from hairport.solver.mesh.areas import signed_areas
from hairport.solver.mesh.parameterization import PARAMETERIZATIONS, parameterize
from hairport.solver.mesh.topology import boundary_loops, euler_characteristic
from hairport.solver.model.errors import InputError


@pytest.fixture(scope="module")
def patch(character, scalp, frame):
    return head_patch(character, scalp, frame=frame)


def test_head_patch_is_a_disk_around_the_scalp(character, frame, scalp, patch):
    vertices, triangles, faces = patch
    assert (len(vertices), len(triangles)) == (721, 1310)  # margin 6 around a 466-face scalp
    assert np.array_equal(character.faces[faces], vertices[triangles])
    assert np.isin(scalp.faces, faces).all()
    assert euler_characteristic(triangles) == 1 and len(boundary_loops(triangles)) == 1
    extra = np.setdiff1d(faces, scalp.faces)
    assert frame.head_vertices[character.faces[extra]].all()
    # margin 0 is the scalp itself; more rings, more faces
    v0, t0, f0 = head_patch(character, scalp, 0, frame)
    assert np.array_equal(f0, scalp.faces) and np.array_equal(v0, scalp.vertices)
    assert len(head_patch(character, scalp, DEFAULT_MARGIN_RINGS + 1, frame)[2]) > len(faces)
    with pytest.raises(InputError, match="margin_rings"):
        head_patch(character, scalp, -1, frame)


@pytest.mark.parametrize("method", PARAMETERIZATIONS)
def test_parameterizations_of_the_head_patch_are_injective_in_the_unit_disk(character, patch, method):
    vertices, triangles, _ = patch
    uv = parameterize(character.vertices[vertices], triangles, method)
    assert uv.shape == (len(vertices), 2)
    radius = np.linalg.norm(uv, axis=1)
    assert radius.max() <= 1.0 + 1e-9
    assert abs(radius.max() - 1.0) < 1e-9  # fitted to the disk, not just inside it
    assert (signed_areas(uv, triangles) > 0).all()
    if method == "harmonic":
        loop = boundary_loops(triangles)[0]
        assert np.abs(radius[loop] - 1.0).max() < 1e-12
        interior = np.setdiff1d(np.arange(len(vertices)), loop)
        assert radius[interior].max() < 1.0


def test_each_margin_ring_adds_the_head_faces_touching_the_patch(character, frame, scalp):
    faces = character.faces
    head = frame.head_vertices[faces].all(axis=1)
    region = np.zeros(len(faces), dtype=bool)
    region[scalp.faces] = True
    for rings, count in ((1, 565), (2, 678), (3, 804)):
        touched = np.zeros(character.n_vertices, dtype=bool)
        touched[faces[region].ravel()] = True
        region |= head & touched[faces].any(axis=1)  # these rings need no disk repair
        vertices, triangles, patch_faces = head_patch(character, scalp, rings, frame)
        assert len(patch_faces) == count
        np.testing.assert_array_equal(patch_faces, np.flatnonzero(region))
        np.testing.assert_array_equal(vertices, np.unique(faces[patch_faces]))
        np.testing.assert_array_equal(vertices[triangles], faces[patch_faces])
