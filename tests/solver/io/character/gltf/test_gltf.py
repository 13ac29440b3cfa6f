"""Tests for solver/io/character/gltf.py: mesh selection, node transforms, malformed and corrupted files."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
import trimesh

from hairport.solver.io.character import load_character
from hairport.solver.io.character.gltf import READERS, read_gltf
from hairport.solver.model.errors import InputError
from tests.solver.io.character.samples import GltfBuilder, skinned_body_gltf


def test_gltf_unskinned_meshes(tmp_path):
    box = trimesh.creation.box()
    builder = GltfBuilder()
    m1 = builder.mesh(box.vertices, box.faces, "left")
    m2 = builder.mesh(box.vertices, box.faces, "right")
    builder.node(name="left_node", mesh=m1, translation=[-2, 0, 0])
    builder.node(name="right_node", mesh=m2, translation=[2, 0, 0], scale=[-1, 1, 1])
    path = tmp_path / "two.glb"
    path.write_bytes(builder.glb())
    with pytest.raises(InputError) as error:
        load_character(path)
    assert error.value.code == "ambiguous_mesh"
    assert "left_node" in error.value.problem and "right_node" in error.value.problem
    left = load_character(path, mesh_name="left_node")
    np.testing.assert_allclose(left.vertices, box.vertices + [-2, 0, 0], atol=1e-6)
    right = load_character(path, mesh_name="right")  # by mesh name; mirrored -> winding flipped
    np.testing.assert_allclose(right.vertices, box.vertices * [-1, 1, 1] + [2, 0, 0], atol=1e-6)
    np.testing.assert_array_equal(right.faces, box.faces[:, [0, 2, 1]])
    assert right.skeleton is None
    with pytest.raises(InputError, match="no mesh named"):
        load_character(path, mesh_name="middle")


def test_glb_bad_input(tmp_path):
    builder, _, _, _ = skinned_body_gltf()
    data = builder.glb()
    path = tmp_path / "cut.glb"
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError) as error:
        load_character(path)
    assert error.value.code == "truncated"
    # an accessor that claims more elements than its bufferView holds
    builder, _, _, _ = skinned_body_gltf()
    builder.doc["accessors"][0]["count"] += 10
    path.write_bytes(builder.glb())
    with pytest.raises(InputError) as error:
        load_character(path)
    assert error.value.code == "truncated"
    # limits are checked from the accessor counts
    builder, _, _, _ = skinned_body_gltf()
    path.write_bytes(builder.glb())
    with pytest.raises(InputError) as error:
        load_character(path, max_vertices=10)
    assert error.value.code == "too_large"
    # a buffer uri escaping the folder is refused: named at all by default, outside the folder when files
    # beside the document may be read
    builder, _, _, _ = skinned_body_gltf()
    builder.gltf(tmp_path / "x.gltf", external=True)
    document = json.loads((tmp_path / "x.gltf").read_text())
    document["buffers"][0]["uri"] = "../../etc/passwd"
    (tmp_path / "x.gltf").write_text(json.dumps(document))
    with pytest.raises(InputError, match="relative path"):
        load_character(tmp_path / "x.gltf", allow_external_files=True)
    with pytest.raises(InputError) as error:
        load_character(tmp_path / "x.gltf")
    assert error.value.code == "external_reference" and "'../../etc/passwd'" in error.value.problem


def test_corrupted_glb_gives_input_errors_only(tmp_path):
    builder, _, _, _ = skinned_body_gltf()
    data = bytearray(builder.glb())
    json_length = struct.unpack_from("<I", data, 12)[0]
    rng = np.random.default_rng(11)
    path = tmp_path / "fuzz.glb"
    for trial in range(60):
        corrupted = bytearray(data)
        if trial % 3 == 0:  # truncate anywhere
            corrupted = corrupted[: int(rng.integers(0, len(data)))]
        else:  # flip a few bytes, mostly in the JSON chunk
            end = 20 + json_length if trial % 3 == 1 else len(data)
            for position in rng.integers(0, end, 3):
                corrupted[position] = int(rng.integers(0, 256))
        path.write_bytes(bytes(corrupted))
        try:
            load_character(path)
        except InputError:
            pass


def one_box(change) -> GltfBuilder:
    box = trimesh.creation.box()
    builder = GltfBuilder()
    builder.node(name="box", mesh=builder.mesh(box.vertices, box.faces, "box"))
    change(builder.doc)
    return builder


@pytest.mark.parametrize(
    "change, code, words",
    [
        (lambda doc: doc["meshes"][0]["primitives"][0].update(mode=1), "bad_faces", "only triangles (4)"),
        (lambda doc: doc["meshes"][0].update(primitives=[]), "empty_mesh", "no primitives"),
        (lambda doc: doc.update(meshes=[]), "empty_mesh", "no mesh"),
        (lambda doc: doc["accessors"][1].update(count=35), "bad_faces", "not a multiple of 3"),
        (lambda doc: doc["nodes"][0].update(mesh=4), "bad_mesh", "meshes[4], which does not exist"),
        (lambda doc: doc["meshes"][0]["primitives"][0]["attributes"].pop("POSITION"), "bad_mesh", "no POSITION"),
    ],
)
def test_bad_meshes(tmp_path, change, code, words):
    path = tmp_path / "box.glb"
    path.write_bytes(one_box(change).glb())
    with pytest.raises(InputError) as error:
        read_gltf(path)
    assert error.value.code == code and words in error.value.problem


def test_one_unskinned_mesh(tmp_path):
    box = trimesh.creation.box()
    path = tmp_path / "box.glb"
    path.write_bytes(one_box(lambda doc: doc["nodes"][0].update(translation=[0, 0, 1])).glb())
    mesh = read_gltf(path)
    assert mesh.name == "box" and mesh.skin is None
    np.testing.assert_allclose(mesh.vertices, box.vertices + [0, 0, 1], atol=1e-7)
    np.testing.assert_array_equal(mesh.faces, box.faces)
    assert READERS[".glb"](path, max_vertices=8, max_faces=12, mesh_name=None).name == "box"
    with pytest.raises(InputError) as error:
        READERS[".gltf"](path, max_vertices=7, max_faces=12, mesh_name=None)
    assert error.value.code == "too_large"
