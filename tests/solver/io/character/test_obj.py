"""Tests for solver/io/character/obj.py: the OBJ reader that keeps vertex order, fan triangulation, the writer."""

from __future__ import annotations

import numpy as np
import pytest

from hairport.solver.io.character import load_character
from hairport.solver.io.character.obj import READERS, fan_triangulate, read_obj, write_obj
from hairport.solver.model.errors import InputError
from tests.solver.io.character.samples import body_triangles, make_body, write_obj_polygons


def test_obj_with_vt_vn_keeps_vertex_count_and_order(tmp_path):
    vertices, quads, tris = make_body()
    polygons = list(quads) + list(tris)
    path = tmp_path / "body.obj"
    write_obj_polygons(path, vertices, polygons, with_attributes=True)
    character = load_character(path)
    np.testing.assert_array_equal(character.vertices, vertices)  # exact: same floats, same order
    np.testing.assert_array_equal(character.faces, body_triangles(quads, tris))
    assert character.skeleton is None and character.name == "body.obj"
    # plain indices give the same topology
    plain = tmp_path / "plain.obj"
    write_obj_polygons(plain, vertices, polygons)
    np.testing.assert_array_equal(load_character(plain).faces, character.faces)


def test_obj_polygons_negative_indices_and_extras(tmp_path):
    path = tmp_path / "poly.obj"
    path.write_text(
        "mtllib x.mtl\nv 0 0 0 1\nv 1 0 0\nv 1 1 0 0.5 0.5 0.5\nv 0 1 0\n"
        "g a\nusemtl m\nf -4 -3 -2 -1\nv 0.5 0.5 1\nvn 0 0 1\nf 1//1 2//1 5//1   # comment\n"
        "f 2 3 \\\n 4 5 1\ns off\nl 1 2\n"
    )
    vertices, faces = read_obj(path)
    np.testing.assert_array_equal(vertices, [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]])
    np.testing.assert_array_equal(faces, [[0, 1, 2], [0, 2, 3], [0, 1, 4], [1, 2, 3], [1, 3, 4], [1, 4, 0]])


def test_fan_triangulate():
    faces = fan_triangulate(np.array([5, 6, 7, 1, 2, 3, 4, 8]), np.array([3, 5]))
    np.testing.assert_array_equal(faces, [[5, 6, 7], [1, 2, 3], [1, 3, 4], [1, 4, 8]])


@pytest.mark.parametrize(
    "text, code",
    [
        ("v 0 0 0\nv 1 0 0\nf 1 2\n", "bad_faces"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "bad_faces"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "bad_faces"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n", "bad_faces"),
        ("v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n", "non_finite"),
        ("v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n", "bad_mesh"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "empty_mesh"),
        ("# nothing\n", "empty_mesh"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n\0\0", "not_text"),  # a binary file named .obj
    ],
)
def test_obj_bad_input(tmp_path, text, code):
    path = tmp_path / "bad.obj"
    path.write_text(text)
    with pytest.raises(InputError) as error:
        load_character(path)
    assert error.value.code == code
    assert error.value.source == str(path)
    assert str(path) in str(error.value)


def test_write_obj_writes_v_and_f_lines_only(tmp_path):
    vertices = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.1234567891234, -2.5, 1e-12]])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    path = tmp_path / "new" / "tri.obj"  # the folder is created
    write_obj(path, vertices, faces, "two triangles")
    assert path.read_text() == (
        "# two triangles\n"
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0.123456789 -2.5 1e-12\n"
        "f 1 2 3\nf 1 3 4\n"
    )
    assert [p.name for p in path.parent.iterdir()] == ["tri.obj"]  # no temporary file left
    read_vertices, read_faces = read_obj(path)
    np.testing.assert_array_equal(read_faces, faces)
    np.testing.assert_array_equal(read_vertices, [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.123456789, -2.5, 1e-12]])


def test_reader_interface(tmp_path):
    vertices, quads, tris = make_body()
    path = tmp_path / "body.obj"
    write_obj_polygons(path, vertices, list(quads) + list(tris))
    mesh = READERS[".obj"](path, max_vertices=10_000, max_faces=10_000, mesh_name="ignored")
    np.testing.assert_array_equal(mesh.vertices, vertices)
    np.testing.assert_array_equal(mesh.faces, body_triangles(quads, tris))
    assert mesh.skin is None and list(READERS) == [".obj"]
