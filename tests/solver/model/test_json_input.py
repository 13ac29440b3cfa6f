"""Hostile JSON and integers in the readers: stable InputError codes, never RecursionError or OverflowError."""

import json

import numpy as np
import pytest

from hairport.solver import InputError, read_character
from hairport.solver.model.json_input import parse_json

DEPTH = 200_000


@pytest.mark.parametrize("document", [b"[" * DEPTH + b"]" * DEPTH, b'{"a":' * DEPTH + b"1" + b"}" * DEPTH])
def test_deep_json_is_too_deep(document):
    with pytest.raises(InputError) as error:
        parse_json(document, "doc.json", "bad_json", "the document")
    assert error.value.code == "too_deep"
    assert error.value.problem == "the document is nested too deeply to be read"


def test_json_that_is_not_utf8_keeps_its_code():
    with pytest.raises(InputError) as error:
        parse_json(b"\xff\xfe", "doc.json", "bad_json")
    assert error.value.code == "bad_json"


def _square(tmp_path, extra=""):
    path = tmp_path / "square.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n" + extra)
    return path


@pytest.mark.parametrize("index", ["9223372036854775808", "-9223372036854775809", "1" + "0" * 40])
def test_obj_face_index_past_int64_is_bad_faces(tmp_path, index):
    with pytest.raises(InputError) as error:
        read_character(_square(tmp_path, f"f 1 2 {index}\n"))
    assert error.value.code == "bad_faces"


def test_deep_skeleton_sidecar_is_too_deep(tmp_path):
    skeleton = tmp_path / "rig.json"
    skeleton.write_bytes(b"[" * DEPTH + b"]" * DEPTH)
    with pytest.raises(InputError) as error:
        read_character(_square(tmp_path), skeleton_path=skeleton)
    assert error.value.code == "too_deep"


@pytest.mark.parametrize("suffix", [".gltf", ".glb"])
def test_deep_gltf_is_too_deep(tmp_path, suffix):
    document = b"[" * DEPTH + b"]" * DEPTH
    if suffix == ".glb":
        document += b" " * (-len(document) % 4)
        body = np.array([len(document), 0x4E4F534A], "<u4").tobytes() + document
        document = b"glTF" + np.array([2, 12 + len(body)], "<u4").tobytes() + body
    path = tmp_path / f"deep{suffix}"
    path.write_bytes(document)
    with pytest.raises(InputError) as error:
        read_character(path)
    assert error.value.code == "too_deep"
    assert json.dumps(error.value.problem)  # a plain message, no traceback
