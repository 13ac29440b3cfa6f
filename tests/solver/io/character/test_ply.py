"""Tests for solver/io/character/ply.py: PLY through trimesh with the file's vertex order, header limits."""

from __future__ import annotations

import numpy as np
import pytest

from hairport.solver.io.character import load_character
from hairport.solver.io.character.ply import READERS, read_ply
from hairport.solver.model.errors import InputError
from tests.solver.io.character.samples import body_triangles, make_body


def test_ply_with_per_face_texcoords_keeps_vertices(tmp_path):
    path = tmp_path / "quads.ply"
    path.write_text(
        "ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 2\nproperty list uchar int vertex_indices\nproperty list uchar float texcoord\nend_header\n"
        "0 0 0\n1 0 0\n1 1 0\n0 1 0\n2 0 0\n2 1 0\n"
        "4 0 1 2 3 8 0 0 1 0 1 1 0 1\n4 1 4 5 2 8 0.1 0 1 0 1 1 0 1\n"
    )
    character = load_character(path)
    assert character.n_vertices == 6 and character.n_faces == 4
    np.testing.assert_array_equal(character.vertices[4], [2, 0, 0])


def test_binary_ply_and_header_limits(tmp_path):
    vertices, quads, tris = make_body()
    faces = body_triangles(quads, tris)
    face_dtype = np.dtype([("n", "u1"), ("i", "<i4", (3,))])
    face_data = np.zeros(len(faces), face_dtype)
    face_data["n"], face_data["i"] = 3, faces
    header = (
        f"ply\nformat binary_little_endian 1.0\nelement vertex {len(vertices)}\nproperty double x\n"
        f"property double y\nproperty double z\nelement face {len(faces)}\n"
        "property list uchar int vertex_indices\nend_header\n"
    ).encode()
    path = tmp_path / "body.ply"
    path.write_bytes(header + vertices.astype("<f8").tobytes() + face_data.tobytes())
    character = load_character(path)
    np.testing.assert_array_equal(character.vertices, vertices)
    np.testing.assert_array_equal(character.faces, faces)
    with pytest.raises(InputError) as error:
        load_character(path, max_faces=10)
    assert error.value.code == "too_large"
    (tmp_path / "junk.ply").write_bytes(b"not a ply")
    with pytest.raises(InputError):
        load_character(tmp_path / "junk.ply")


@pytest.mark.parametrize(
    "header, words",
    [
        (b"ply\nformat ascii 1.0\nelement vertex 3\n", "no end_header"),
        (b"ply\nformat ascii 1.0\nelement vertex three\nend_header\n", "bad count"),
        (b"ply\nformat ascii 1.0\nelement vertex -3\nend_header\n", "negative element count"),
        (b"PLY\nend_header\n", "no 'ply' magic"),
    ],
)
def test_bad_headers(tmp_path, header, words):
    path = tmp_path / "bad.ply"
    path.write_bytes(header)
    with pytest.raises(InputError) as error:
        read_ply(path)
    assert error.value.code == "bad_mesh" and words in error.value.problem


def test_header_counts_are_checked_before_the_body(tmp_path):
    path = tmp_path / "huge.ply"  # a header that promises more than the limit, and no body at all
    path.write_bytes(b"ply\nformat ascii 1.0\nelement vertex 5000000\nelement face 1\nend_header\n")
    with pytest.raises(InputError, match="5000000 vertices") as error:
        read_ply(path)
    assert error.value.code == "too_large"
    assert list(READERS) == [".ply"]
