"""Tests for solver/io/character/export.py: a character written as OBJ + sidecar and read back."""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.sparse as sp
import trimesh

from hairport.solver.io.character import load_character, write_character
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError
from hairport.solver.synthetic.makehuman import build_preset
from hairport.solver.synthetic.toy import toy_character
from tests.solver.synthetic.makehuman_fixtures import makehuman_assets

#: ``%.9g`` keeps 9 significant digits: the toy's coordinates (< 2 m) come back within this (m)
ROUND_TRIP_TOLERANCE_M = 1e-8


def test_round_trip(tmp_path):
    toy = toy_character()
    write_character(toy, tmp_path / "toy.obj", tmp_path / "toy.skeleton.json")
    header = (tmp_path / "toy.obj").read_text().split("\n", 2)[:2]
    assert header[0] == f"# toy: {toy.n_vertices} vertices, {toy.n_faces} triangles, meters, Y up"
    assert header[1].startswith("v ")
    loaded = load_character(tmp_path / "toy.obj")  # finds the sidecar beside the mesh
    assert loaded.name == "toy.obj"
    np.testing.assert_array_equal(loaded.faces, toy.faces)
    assert np.abs(loaded.vertices - toy.vertices).max() < ROUND_TRIP_TOLERANCE_M
    assert loaded.skeleton.names == toy.skeleton.names
    np.testing.assert_array_equal(loaded.skeleton.parents, toy.skeleton.parents)
    np.testing.assert_array_equal(loaded.skeleton.heads, toy.skeleton.heads)  # JSON keeps every digit
    np.testing.assert_allclose(loaded.weights.toarray(), toy.weights.toarray(), rtol=1e-15, atol=0)


def test_without_weights_every_bone_gets_an_empty_entry(tmp_path):
    toy = toy_character()
    bare = Character(toy.vertices, toy.faces, toy.skeleton, None, "bare")
    write_character(bare, tmp_path / "bare.obj", tmp_path / "bare.skeleton.json")
    document = json.loads((tmp_path / "bare.skeleton.json").read_text())
    assert document["weights"] == {name: [] for name in toy.skeleton.names}
    loaded = load_character(tmp_path / "bare.obj")
    assert loaded.weights.shape == (toy.n_vertices, toy.skeleton.n_bones) and loaded.weights.nnz == 0


def test_without_skeleton_nothing_is_written(tmp_path):
    toy = toy_character()
    with pytest.raises(InputError) as error:
        write_character(Character(toy.vertices, toy.faces, name="mesh"), tmp_path / "m.obj", tmp_path / "m.json")
    assert error.value.code == "bad_skeleton" and error.value.source == "mesh"
    assert list(tmp_path.iterdir()) == []


def test_write_makehuman_character(tmp_path):
    character = build_preset("child", makehuman_assets())
    mesh_path, skeleton_path = tmp_path / "child.obj", tmp_path / "child.skeleton.json"
    write_character(character, mesh_path, skeleton_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["child.obj", "child.skeleton.json"]

    mesh = trimesh.load(mesh_path, process=False, force="mesh")
    assert np.abs(mesh.vertices - character.vertices).max() < 1e-8
    assert np.array_equal(mesh.faces, character.faces)

    doc = json.loads(skeleton_path.read_text())
    assert set(doc) == {"units", "bones", "weights"}
    assert doc["units"] == "m"
    sk = character.skeleton
    assert [b["name"] for b in doc["bones"]] == list(sk.names)
    for b, bone in enumerate(doc["bones"]):
        assert set(bone) == {"name", "parent", "head", "tail"}
        assert bone["parent"] == (sk.names[sk.parents[b]] if sk.parents[b] >= 0 else None)
        assert np.allclose(bone["head"], sk.heads[b]) and np.allclose(bone["tail"], sk.tails[b])
        assert len(bone["head"]) == len(bone["tail"]) == 3
    assert doc["bones"][0]["parent"] is None
    assert set(doc["weights"]) <= set(sk.names)
    rows, cols, vals = [], [], []
    for name, pairs in doc["weights"].items():
        for vertex, weight in pairs:
            assert isinstance(vertex, int) and isinstance(weight, float)
            rows.append(vertex)
            cols.append(sk.index(name))
            vals.append(weight)
    rebuilt = sp.csr_matrix((vals, (rows, cols)), shape=character.weights.shape)
    assert abs(rebuilt - character.weights).max() < 1e-15
