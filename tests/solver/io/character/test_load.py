"""Tests for solver/io/character/load.py: the format registry, file checks, limits, units, where the skeleton comes from."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hairport.solver.io.character import load_character, resolve_skeleton_path
from hairport.solver.io.character.load import MESH_EXTENSIONS, MESH_READERS
from hairport.solver.model.errors import InputError
from tests.solver.io.character.samples import BONES, body_obj, make_body, skinned_body_gltf, write_obj_polygons


def test_file_errors(tmp_path):
    with pytest.raises(InputError) as error:
        load_character(tmp_path / "missing.obj")
    assert error.value.code == "not_found"
    (tmp_path / "mesh.stl").write_text("solid x\n")
    with pytest.raises(InputError) as error:
        load_character(tmp_path / "mesh.stl")
    assert error.value.code == "unknown_format"
    (tmp_path / "empty.obj").write_bytes(b"")
    with pytest.raises(InputError) as error:
        load_character(tmp_path / "empty.obj")
    assert error.value.code == "empty_mesh"


def test_limits(tmp_path):
    vertices, quads, tris = make_body()
    path = tmp_path / "body.obj"
    write_obj_polygons(path, vertices, list(quads) + list(tris))
    with pytest.raises(InputError, match="vertices") as error:
        load_character(path, max_vertices=100)
    assert error.value.code == "too_large"
    with pytest.raises(InputError, match="triangles|faces") as error:
        load_character(path, max_faces=len(quads) + len(tris))  # fine as polygons, too many triangles
    assert error.value.code == "too_large"
    with pytest.raises(InputError) as error:
        load_character(path, max_bytes=100)
    assert error.value.code == "too_large"


def test_units_conversion(tmp_path):
    vertices, quads, tris = make_body()
    path = tmp_path / "body.obj"
    write_obj_polygons(path, vertices * 10.0, list(quads) + list(tris))
    character = load_character(path, units="dm")
    np.testing.assert_allclose(character.vertices, vertices, rtol=1e-15, atol=1e-15)
    with pytest.raises(InputError) as error:
        load_character(path, units="inch")
    assert error.value.code == "unknown_units"


def test_no_sidecar_means_no_skeleton(tmp_path):
    path, _, _ = body_obj(tmp_path)
    assert resolve_skeleton_path(path) is None
    assert load_character(path).skeleton is None
    with pytest.raises(InputError) as error:
        load_character(path, skeleton_path=tmp_path / "nope.json")
    assert error.value.code == "not_found"


def test_gltf_sidecar_wins_over_skin(tmp_path):
    builder, vertices, _, _ = skinned_body_gltf()
    path = tmp_path / "body.glb"
    path.write_bytes(builder.glb())
    (tmp_path / "body.skeleton.json").write_text(json.dumps({"bones": BONES[:2]}))
    assert load_character(path).skeleton.names == ("pelvis", "spine")


def test_derived_weights_follow_the_bones(tmp_path):
    path, vertices, _ = body_obj(tmp_path)
    (tmp_path / "body.skeleton.json").write_text(json.dumps({"units": "m", "bones": BONES}))
    character = load_character(path)
    weights = character.weights.toarray()
    np.testing.assert_allclose(weights.sum(axis=1), 1.0)
    assert (weights >= 0).all()
    z = vertices[:, 2]
    assert (weights[z < -0.3].argmax(axis=1) == 0).all()
    assert (weights[(z > 0.0) & (z < 0.2)].argmax(axis=1) == 1).all()
    assert (weights[z > 0.45].argmax(axis=1) == 2).all()
    # smoothing blends across the border at z = -0.1, hard weights do not
    assert ((weights > 0.05) & (weights < 0.95)).any()
    hard = load_character(path, weight_smoothing=0).weights
    assert set(np.unique(hard.data)) == {1.0}


def test_registry_lists_every_format_once():
    assert MESH_EXTENSIONS == (".obj", ".ply", ".glb", ".gltf", ".usd", ".usda", ".usdc", ".abc")
    assert tuple(MESH_READERS) == MESH_EXTENSIONS
    assert MESH_READERS[".glb"] is MESH_READERS[".gltf"]
    assert MESH_READERS[".usd"] is MESH_READERS[".usda"] is MESH_READERS[".usdc"]


def test_extension_is_matched_case_insensitively(tmp_path):
    path, vertices, faces = body_obj(tmp_path)
    upper = path.rename(tmp_path / "BODY.OBJ")
    character = load_character(upper)
    np.testing.assert_array_equal(character.vertices, vertices)
    np.testing.assert_array_equal(character.faces, faces)
    assert character.name == "BODY.OBJ"


def test_read_character_says_which_units_the_files_state(tmp_path):
    """Given units win; then a sidecar's ``units``; glTF is meters; an OBJ alone or a sidecar without
    ``units`` states none (its coordinates come as they are, weights wait for the units)."""
    from hairport.solver.io.character.load import read_character

    path, vertices, _ = body_obj(tmp_path)
    character, units = read_character(path)
    assert units is None and np.array_equal(character.vertices, vertices)
    assert read_character(path, units="cm")[1] == "cm" and read_character(path, units="auto")[1] is None
    sidecar = tmp_path / "body.skeleton.json"
    sidecar.write_text(json.dumps({"bones": BONES}))
    character, units = read_character(path)
    assert units is None and character.skeleton is not None and character.weights is None
    assert load_character(path).weights is not None  # read as meters, weights derived at once
    sidecar.write_text(json.dumps({"units": "dm", "bones": BONES}))
    character, units = read_character(path)
    assert units == "dm" and np.allclose(character.vertices, vertices * 0.1) and character.weights is not None
    builder, _, _, _ = skinned_body_gltf()
    glb = tmp_path / "skinned.glb"
    glb.write_bytes(builder.glb())
    assert read_character(glb)[1] == "m"
