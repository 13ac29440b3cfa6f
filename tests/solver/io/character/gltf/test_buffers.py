"""Tests for solver/io/character/gltf/buffers.py: GLB chunks, buffers (embedded, data URI, external file), accessors, node transforms."""

from __future__ import annotations

import base64
import json
import struct

import numpy as np
import pytest

from hairport.solver.io.character import load_character
from hairport.solver.io.character.gltf.buffers import (
    GLB_BIN_CHUNK,
    GLB_JSON_CHUNK,
    GLB_MAGIC,
    GltfReader,
    read_gltf_container,
)
from hairport.solver.model.errors import InputError
from tests.solver.io.character.samples import BONES_HEADS, skinned_body_gltf


@pytest.mark.parametrize("external", [True, False])
def test_gltf_buffers(tmp_path, external):
    builder, vertices, _, _ = skinned_body_gltf()
    path = tmp_path / "body.gltf"
    builder.gltf(path, external)
    # explicit units scale mesh and skin alike; a buffer file beside the document is read when allowed
    character = load_character(path, units="cm", allow_external_files=True)
    np.testing.assert_allclose(character.vertices, vertices * 0.01, atol=1e-8)
    np.testing.assert_allclose(character.skeleton.heads, np.array(BONES_HEADS) * 0.01, atol=1e-8)


def reader_over(blob: bytes, accessors: list, views: list, tmp_path, nodes=None) -> GltfReader:
    """A reader over one embedded buffer ``blob`` (the GLB binary chunk)."""
    document = {"buffers": [{"byteLength": len(blob)}], "bufferViews": views, "accessors": accessors,
                "nodes": nodes or []}
    return GltfReader(document, blob, tmp_path / "x.glb")


def test_strided_accessor(tmp_path):
    # two VEC3 float32 positions interleaved with one float32 of something else: stride 16 bytes
    interleaved = np.array([[1, 2, 3, -1], [4, 5, 6, -1]], dtype="<f4").tobytes()
    reader = reader_over(
        interleaved,
        [{"bufferView": 0, "componentType": 5126, "count": 2, "type": "VEC3"},
         {"bufferView": 0, "byteOffset": 12, "componentType": 5126, "count": 2, "type": "SCALAR"}],
        [{"buffer": 0, "byteLength": 32, "byteStride": 16}],
        tmp_path,
    )
    np.testing.assert_array_equal(reader.accessor(0), [[1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(reader.accessor(1), [[-1], [-1]])
    assert reader.accessor(0).dtype == np.float32 and reader.count(0, "POSITION") == 2


def test_misaligned_and_normalised_accessors(tmp_path):
    blob = b"\0" + np.array([1.5, -2.0], dtype="<f4").tobytes() + bytes([0, 255, 51]) + np.array([-128, 127], "i1").tobytes()
    reader = reader_over(
        blob,
        [{"bufferView": 0, "byteOffset": 1, "componentType": 5126, "count": 2, "type": "SCALAR"},
         {"bufferView": 0, "byteOffset": 9, "componentType": 5121, "count": 3, "type": "SCALAR", "normalized": True},
         {"bufferView": 0, "byteOffset": 12, "componentType": 5120, "count": 2, "type": "SCALAR", "normalized": True},
         {"componentType": 5123, "count": 2, "type": "VEC2"}],  # no bufferView: zeros
        [{"buffer": 0, "byteLength": len(blob)}],
        tmp_path,
    )
    np.testing.assert_array_equal(reader.accessor(0), [[1.5], [-2.0]])
    np.testing.assert_array_equal(reader.accessor(1), [[0.0], [1.0], [0.2]])
    np.testing.assert_array_equal(reader.accessor(2), [[-1.0], [1.0]])  # -128 / 127 is clamped to -1
    np.testing.assert_array_equal(reader.accessor(3), np.zeros((2, 2)))


@pytest.mark.parametrize(
    "accessor, view, code, words",
    [
        ({"sparse": {}}, {}, "bad_mesh", "sparse accessors are not supported"),
        ({"componentType": 5130}, {}, "bad_mesh", "unknown component type"),
        ({"count": 3}, {}, "truncated", "runs past the end of its bufferView"),
        ({"byteOffset": 4}, {}, "truncated", "runs past the end of its bufferView"),
        ({}, {"byteStride": 2}, "truncated", "stride or length is invalid"),
        ({}, {"byteLength": 100}, "truncated", "stride or length is invalid"),
        ({"count": -1}, {}, "bad_mesh", "bad count"),
        ({"bufferView": 5}, {}, "bad_mesh", "bufferViews[5], which does not exist"),
    ],
)
def test_bad_accessors(tmp_path, accessor, view, code, words):
    blob = np.zeros(2, dtype="<f4").tobytes()
    reader = reader_over(
        blob,
        [{"bufferView": 0, "componentType": 5126, "count": 2, "type": "SCALAR", **accessor}],
        [{"buffer": 0, "byteLength": 8, **view}],
        tmp_path,
    )
    with pytest.raises(InputError) as error:
        reader.accessor(0)
    assert error.value.code == code and words in error.value.problem


def test_buffer_sources(tmp_path):
    (tmp_path / "data.bin").write_bytes(b"abcd")
    document = {"buffers": [
        {"uri": "data.bin", "byteLength": 4},
        {"uri": "data:application/octet-stream;base64," + base64.b64encode(b"xyz").decode(), "byteLength": 3},
        {"byteLength": 2},
        {"uri": "data.bin", "byteLength": 5},
        {"uri": "/etc/passwd"},
        {"uri": "missing.bin"},
        {"uri": "data:nocomma"},
    ]}
    reader = GltfReader(document, b"GL", tmp_path / "x.gltf", allow_external_files=True)
    assert reader.buffer(0) == b"abcd" and reader.buffer(1) == b"xyz" and reader.buffer(2) == b"GL"
    for index, code, words in [(3, "truncated", "declares 5 bytes but holds 4"),
                               (4, "bad_mesh", "must be a relative path"),
                               (5, "not_found", "not found"),
                               (6, "bad_mesh", "malformed data uri")]:
        with pytest.raises(InputError) as error:
            reader.buffer(index)
        assert error.value.code == code and words in error.value.problem, index
    with pytest.raises(InputError, match="no binary chunk"):
        GltfReader(document, None, tmp_path / "x.gltf").buffer(2)


def test_node_transforms(tmp_path):
    half = np.sqrt(0.5)
    nodes = [
        {"translation": [1, 2, 3], "rotation": [0, 0, half, half], "scale": [2, 1, 1], "children": [1]},
        {"matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 10, 0, 0, 1]},  # column-major: translation (10, 0, 0)
        {},
    ]
    reader = reader_over(b"", [], [], tmp_path, nodes)
    parent = reader.local_matrix(nodes[0])
    # +x is scaled by 2 and turned 90 degrees about z onto +y, then translated
    np.testing.assert_allclose(parent @ [1, 0, 0, 1], [1, 4, 3, 1], atol=1e-15)
    np.testing.assert_allclose(parent @ [0, 1, 0, 1], [0, 2, 3, 1], atol=1e-15)
    np.testing.assert_array_equal(reader.parents(), [-1, 0, -1])
    world = reader.world_matrices()
    np.testing.assert_allclose(world[1][:3, 3], [1, 22, 3], atol=1e-14)  # (10, 0, 0) scaled, turned, moved
    np.testing.assert_array_equal(world[2], np.eye(4))


@pytest.mark.parametrize(
    "nodes, words",
    [
        ([{"children": [1]}, {"children": [0]}], "cycle"),
        ([{"children": [2]}, {"children": [2]}, {}], "invalid or shared child"),
        ([{"children": [7]}], "invalid or shared child"),
        ([{"matrix": [1, 0, 0]}], "16 numbers"),
    ],
)
def test_bad_node_hierarchies(tmp_path, nodes, words):
    reader = reader_over(b"", [], [], tmp_path, nodes)
    with pytest.raises(InputError) as error:
        reader.world_matrices()
    assert error.value.code == "bad_mesh" and words in error.value.problem


def glb(json_bytes: bytes, chunk_type: int = GLB_JSON_CHUNK, version: int = 2) -> bytes:
    body = struct.pack("<II", len(json_bytes), chunk_type) + json_bytes
    return GLB_MAGIC + struct.pack("<II", version, 12 + len(body)) + body


@pytest.mark.parametrize(
    "data, code, words",
    [
        (GLB_MAGIC + b"\x02\0\0\0", "truncated", "no chunk header"),
        (glb(b'{"asset": {}}', version=1), "bad_mesh", "version 1"),
        (glb(b'{"asset": {}}', chunk_type=GLB_BIN_CHUNK), "bad_mesh", "JSON chunk"),
        (glb(b"[1, 2]    "), "bad_mesh", "not an object"),
        (b"{not json", "bad_mesh", "not valid JSON"),
    ],
)
def test_bad_containers(tmp_path, data, code, words):
    path = tmp_path / "bad.glb"
    path.write_bytes(data)
    with pytest.raises(InputError) as error:
        read_gltf_container(path)
    assert error.value.code == code and words in error.value.problem


def test_containers(tmp_path):
    path = tmp_path / "a.glb"
    path.write_bytes(glb(b'{"asset": {"version": "2.0"}}   '))
    assert read_gltf_container(path) == ({"asset": {"version": "2.0"}}, None)
    path = tmp_path / "a.gltf"
    path.write_text('{"asset": {"version": "2.0"}}')
    assert read_gltf_container(path) == ({"asset": {"version": "2.0"}}, None)


def test_an_upload_naming_a_file_by_a_buffer_or_image_uri_is_refused(tmp_path):
    builder, vertices, _, _ = skinned_body_gltf()
    path = tmp_path / "body.gltf"
    builder.gltf(path, external=True)  # buffer.bin beside it: in the blob store, another upload
    with pytest.raises(InputError) as error:
        load_character(path)
    assert error.value.code == "external_reference" and "/buffers/0 uri 'buffer.bin'" in error.value.problem
    assert len(load_character(path, allow_external_files=True).vertices) == len(vertices)
    # a self-contained document naming a file by an image (never read) or an extension's uri is refused too;
    # images held as data: URIs are not
    builder.gltf(path, external=False)
    document = json.loads(path.read_text())
    png = "data:image/png;base64," + base64.b64encode(b"\x89PNG\r\n\x1a\n").decode()
    for images, named in (([{"uri": png}, {"uri": "/etc/passwd"}], "/images/1 uri '/etc/passwd'"),
                          ([{"uri": png, "extensions": {"X_any": {"uri": "../../x.ktx2"}}}],
                           "/images/0/extensions/X_any uri '../../x.ktx2'")):
        path.write_text(json.dumps({**document, "images": images}))
        with pytest.raises(InputError) as error:
            load_character(path)
        assert error.value.code == "external_reference" and named in error.value.problem
        assert len(load_character(path, allow_external_files=True).vertices) == len(vertices)
    path.write_text(json.dumps({**document, "images": [{"uri": png}]}))
    assert len(load_character(path).vertices) == len(vertices)


def test_a_glb_naming_a_second_buffer_file_is_refused(tmp_path):
    builder, _, _, _ = skinned_body_gltf()
    data = builder.glb()
    json_length = struct.unpack_from("<I", data, 12)[0]
    document = json.loads(data[20:20 + json_length])
    document["buffers"].append({"uri": "/srv/storage/blobs/ab/other.bin", "byteLength": 4})
    reader = GltfReader(document, data[28 + json_length:], tmp_path / "x.glb")
    with pytest.raises(InputError) as error:
        reader.buffer(1)
    assert error.value.code == "external_reference" and "buffer 1 uri" in error.value.problem
    text = json.dumps(document).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<II", len(text), GLB_JSON_CHUNK) + text + data[20 + json_length:]
    (tmp_path / "x.glb").write_bytes(GLB_MAGIC + struct.pack("<II", 2, 12 + len(body)) + body)
    with pytest.raises(InputError) as error:
        load_character(tmp_path / "x.glb")
    assert error.value.code == "external_reference" and "/buffers/1 uri" in error.value.problem
