"""Tests for solver/io/character/skeleton_json.py: the skeleton sidecar (read, validate, write, find)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.sparse as sp

from hairport.solver.io.character import load_character
from hairport.solver.io.character.skeleton_json import (
    load_skeleton_json,
    read_skeleton_json,
    resolve_skeleton_path,
    skeleton_document,
    write_skeleton_json,
)
from hairport.solver.model.character import Skeleton
from hairport.solver.model.errors import InputError
from tests.solver.io.character.samples import BONES, body_obj


def test_skeleton_roundtrip_in_centimeters(tmp_path):
    path, vertices, faces = body_obj(tmp_path)
    skeleton = Skeleton([b["name"] for b in BONES], [-1, 0, 1], [b["head"] for b in BONES],
                        [b["tail"] for b in BONES])
    rng = np.random.default_rng(3)
    dense = rng.random((len(vertices), 3)) * (rng.random((len(vertices), 3)) < 0.5)
    dense[0] = 0  # an unweighted vertex stays unweighted
    dense[1:] /= np.maximum(dense[1:].sum(axis=1, keepdims=True), 1e-300)
    dense[1:][dense[1:].sum(axis=1) == 0, 0] = 1.0
    weights = sp.csr_matrix(dense)
    sidecar = tmp_path / "out" / "rig.json"
    write_skeleton_json(sidecar, skeleton, weights, units="cm")
    assert [p.name for p in sidecar.parent.iterdir()] == ["rig.json"]  # no temp file left
    document = json.loads(sidecar.read_text())
    assert document["units"] == "cm" and document["bones"][1]["parent"] == "pelvis"
    assert document["bones"][2]["head"] == pytest.approx([0, 0, 30])
    loaded, loaded_weights = load_skeleton_json(sidecar, len(vertices))
    np.testing.assert_allclose(loaded.heads, skeleton.heads, atol=1e-15)
    np.testing.assert_allclose(loaded.tails, skeleton.tails, atol=1e-15)
    np.testing.assert_array_equal(loaded.parents, skeleton.parents)
    np.testing.assert_allclose(loaded_weights.toarray(), dense, atol=1e-15)


def test_sidecar_is_found_and_sets_mesh_units(tmp_path):
    path, vertices, faces = body_obj(tmp_path, scale=100.0)  # mesh written in cm
    bones = [dict(b, head=[100 * x for x in b["head"]], tail=[100 * x for x in b["tail"]]) for b in BONES]
    weights = {"pelvis": [[i, 1.0] for i in range(len(vertices))], "spine": [[0, 3.0], [0, 1.0]]}
    sidecar = tmp_path / "body.skeleton.json"
    sidecar.write_text(json.dumps({"units": "cm", "bones": bones, "weights": weights, "extra": 1}))
    assert resolve_skeleton_path(path) == sidecar
    character = load_character(path)
    np.testing.assert_allclose(character.vertices, vertices, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(character.skeleton.heads, [b["head"] for b in BONES], atol=1e-15)
    # rows normalised; duplicate entries summed: vertex 0 has pelvis 1, spine 4 -> 0.2 / 0.8
    np.testing.assert_allclose(character.weights[0].toarray(), [[0.2, 0.8, 0.0]])
    np.testing.assert_allclose(np.asarray(character.weights.sum(axis=1)).ravel(), 1.0)
    # explicit units win over the sidecar's
    assert np.allclose(load_character(path, units="m").vertices, vertices * 100.0)


def _bones(**changes):
    bones = [dict(b) for b in BONES]
    for index, change in changes.items():
        bones[int(index[1:])].update(change)
    return bones


@pytest.mark.parametrize(
    "document, code, words",
    [
        ({"bones": _bones(b1={"parent": "hips"})}, "bad_skeleton", "unknown parent"),
        ({"bones": _bones(b2={"name": "spine"})}, "bad_skeleton", "duplicate"),
        ({"bones": _bones(b0={"parent": "head"})}, "bad_skeleton", "cycle"),
        ({"bones": _bones(b1={"parent": "spine"})}, "bad_skeleton", "cycle"),
        ({"bones": _bones(b1={"head": [0, "x", 0]})}, "bad_skeleton", "3 numbers"),
        ({"bones": _bones(b1={"tail": [0, 0]})}, "bad_skeleton", "3 numbers"),
        ({"bones": _bones(b1={"tail": [0, float("inf"), 0]})}, "non_finite", "non-finite"),
        ({"bones": []}, "bad_skeleton", "bones"),
        ({"units": "ft", "bones": BONES}, "unknown_units", "unit"),
        ({"bones": BONES, "weights": {"tail": [[0, 1]]}}, "bad_weights", "unknown bone"),
        ({"bones": BONES, "weights": {"head": [[100000, 1]]}}, "bad_weights", "outside"),
        ({"bones": BONES, "weights": {"head": [[-1, 1]]}}, "bad_weights", "outside"),
        ({"bones": BONES, "weights": {"head": [[1.5, 1]]}}, "bad_weights", "non-integer"),
        ({"bones": BONES, "weights": {"head": [[1, -0.5]]}}, "bad_weights", "negative"),
        ({"bones": BONES, "weights": {"head": [[1, float("nan")]]}}, "non_finite", "non-finite"),
        ({"bones": BONES, "weights": {"head": [[1, 2, 3]]}}, "bad_weights", "pairs"),
        ({"bones": BONES, "weights": [1, 2]}, "bad_weights", "object"),
        ([1, 2], "bad_skeleton", "object"),
    ],
)
def test_sidecar_validation(tmp_path, document, code, words):
    path = tmp_path / "rig.json"
    path.write_text(json.dumps(document))  # json writes NaN / Infinity tokens, as some exporters do
    with pytest.raises(InputError) as error:
        load_skeleton_json(path, 100)
    assert error.value.code == code
    assert words in error.value.problem
    assert error.value.source == str(path)


def test_sidecar_not_json(tmp_path):
    path = tmp_path / "rig.json"
    path.write_text("{bones: ")
    with pytest.raises(InputError, match="JSON") as error:
        load_skeleton_json(path, 10)
    assert error.value.code == "bad_skeleton"


@pytest.mark.parametrize(
    "document",
    [
        {"bones": [None]},
        {"bones": [{"name": "a", "parent": None, "head": [10**400, 0, 0], "tail": [0, 0, 1]}]},
        {"bones": "abc"},
        {"bones": BONES, "weights": {"head": "abc"}},
        {"bones": BONES, "weights": {"head": [[1, [2]]]}},
        {"bones": BONES, "weights": {"head": [None]}},
        {"units": None, "bones": BONES},
    ],
)
def test_malformed_sidecar_gives_input_error(tmp_path, document):
    path = tmp_path / "rig.json"
    path.write_text(json.dumps(document))
    with pytest.raises(InputError):
        load_skeleton_json(path, 100)


def chain() -> Skeleton:
    return Skeleton([b["name"] for b in BONES], [-1, 0, 1], [b["head"] for b in BONES], [b["tail"] for b in BONES])


def test_skeleton_document():
    weights = sp.csr_matrix(np.array([[0.25, 0.75, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]))
    assert skeleton_document(chain(), weights, units="dm") == {
        "units": "dm",
        "bones": [
            {"name": "pelvis", "parent": None, "head": [0.0, 0.0, -5.0], "tail": [0.0, 0.0, -1.0]},
            {"name": "spine", "parent": "pelvis", "head": [0.0, 0.0, -1.0], "tail": [0.0, 0.0, 3.0]},
            {"name": "head", "parent": "spine", "head": [0.0, 0.0, 3.0], "tail": [0.0, 0.0, 6.0]},
        ],
        "weights": {"pelvis": [[0, 0.25]], "spine": [[0, 0.75]], "head": [[2, 1.0]]},
    }
    assert "weights" not in skeleton_document(chain(), None)
    with pytest.raises(InputError) as error:
        skeleton_document(chain(), sp.csr_matrix((3, 2)), source="rig.json")
    assert error.value.code == "bad_weights" and error.value.source == "rig.json"


def test_write_keeps_the_callers_weights(tmp_path):
    weights = sp.csc_matrix(np.array([[1.0, 0.0, 0.0], [0.0, 0.5, 0.5]]))
    weights.data[0] = 0.0  # an explicit zero, not written
    before = (weights.indptr.copy(), weights.indices.copy(), weights.data.copy())
    write_skeleton_json(tmp_path / "rig.json", chain(), weights)
    assert json.loads((tmp_path / "rig.json").read_text())["weights"] == {
        "pelvis": [], "spine": [[1, 0.5]], "head": [[1, 0.5]]
    }
    for array, copy in zip((weights.indptr, weights.indices, weights.data), before):
        np.testing.assert_array_equal(array, copy)


def test_read_returns_the_units(tmp_path):
    path = tmp_path / "rig.json"
    write_skeleton_json(path, chain(), None, units="mm")
    skeleton, weights, units = read_skeleton_json(path, 10, 1 << 20)
    assert units == "mm" and weights is None
    np.testing.assert_allclose(skeleton.tails, chain().tails, rtol=1e-15)
    with pytest.raises(InputError) as error:
        read_skeleton_json(path, 10, 100)  # the file is larger than 100 bytes
    assert error.value.code == "too_large"
