"""The head patch around the scalp: a disk of head faces, parameterizable by every method."""

import numpy as np
import pytest

from hairport.solver.body.head_frame import head_frame
from hairport.solver.hairline import head_patch as head_patch_module
from hairport.solver.hairline.head_patch import GAP_CLEARANCE_FACTOR, default_margin_rings, head_patch
from hairport.solver.hairline.scalp import extract_scalp
from hairport.solver.mesh.areas import signed_areas, triangle_areas
from hairport.solver.mesh.parameterization import PARAMETERIZATIONS, parameterize
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.mesh.shells import border_vertices, edge_distance
from hairport.solver.mesh.topology import boundary_loops, euler_characteristic
from hairport.solver.model.errors import InputError
from tests.solver.hairline.real_meshes import subdivided


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
    assert default_margin_rings(character, scalp, frame) == 6
    np.testing.assert_array_equal(head_patch(character, scalp, 6, frame)[2], faces)
    assert len(head_patch(character, scalp, 7, frame)[2]) > len(faces)
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


def test_the_head_patch_on_a_bust_is_the_one_on_the_body(character, patch, bust, bust_roots):
    on_bust = head_patch(bust, extract_scalp(bust, bust_roots))
    assert (len(on_bust[0]), len(on_bust[1])) == (721, 1310)
    np.testing.assert_array_equal(bust.vertices[on_bust[0]], character.vertices[patch[0]])
    np.testing.assert_array_equal(on_bust[1], patch[1])


def test_the_head_patch_keeps_clear_of_a_gap_in_the_mesh(gapped, monkeypatch):
    holed, gap, root_faces, _ = gapped
    scalp = extract_scalp(holed, root_faces)
    vertices, triangles, faces = head_patch(holed, scalp)
    assert euler_characteristic(triangles) == 1 and len(boundary_loops(triangles)) == 1
    border = border_vertices(holed.faces, holed.n_vertices)
    assert border.sum() == 6 and not border[vertices].any()
    # a face joins when its corners are at most twice as far from the scalp as from the gap
    assert len(faces) == 1260
    at_scalp = np.zeros(holed.n_vertices, dtype=bool)
    at_scalp[scalp.vertices] = True
    to_scalp = edge_distance(holed.vertices, holed.faces, at_scalp)[vertices]
    to_gap = edge_distance(holed.vertices, holed.faces, border)[vertices]
    assert (to_scalp <= GAP_CLEARANCE_FACTOR * to_gap).all()
    assert np.linalg.norm(holed.vertices[vertices] - gap, axis=1).min() > 0.008
    # without it six rings reach around the gap, and the margin loses rings everywhere
    monkeypatch.setattr(head_patch_module, "GAP_CLEARANCE_FACTOR", 1e9)
    assert len(head_patch(holed, scalp)[2]) == 1094


def test_the_margin_keeps_its_size_on_a_finer_mesh(character, roots, patch):
    """1-to-4 subdivided, the head has 4x the faces: twice the rings, the same area (m^2)."""
    finer = subdivided(character)
    finer_scalp = extract_scalp(finer, MeshQuery(finer.vertices, finer.faces).signed_distance(roots[0]).faces)
    assert default_margin_rings(finer, finer_scalp, head_frame(finer)) == 12
    vertices, triangles, faces = head_patch(finer, finer_scalp)
    assert len(faces) == 5061
    area = triangle_areas(character.vertices[patch[0]], patch[1]).sum()
    assert area == pytest.approx(0.0617, abs=1e-4)
    assert triangle_areas(finer.vertices[vertices], triangles).sum() == pytest.approx(area, rel=0.01)
