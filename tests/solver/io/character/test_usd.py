"""USD characters (:mod:`hairport.solver.io.character.usd`): the skinned mesh of a stage, its skeleton and
weights, fan triangulation, the stage's units, bad input."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom, Vt

from hairport.solver.io.character.load import load_character, read_character
from hairport.solver.io.character.mesh_file import fan_triangles
from hairport.solver.model.errors import InputError
from hairport.solver.synthetic import toy
from tests.solver.io.character.usd_samples import Y_UP_TO_Z_UP, write_scene

#: integration, not unit: every USD read runs in a sandboxed child process
pytestmark = pytest.mark.integration


def expect(code: str, path, **kwargs) -> InputError:
    with pytest.raises(InputError) as caught:
        load_character(path, **kwargs)
    assert caught.value.code == code, caught.value
    return caught.value


def quad_stage(path, counts, indices, points, meters_per_unit=1.0):
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    mesh = UsdGeom.Mesh.Define(stage, "/quad")
    mesh.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, p)) for p in points]))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray(counts))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray(indices))
    stage.GetRootLayer().Save()


def test_fans_keep_the_file_order_of_faces_and_corners():
    triangles = fan_triangles(np.array([4, 3, 5]), np.arange(12))
    assert triangles.tolist() == [[0, 1, 2], [0, 2, 3], [4, 5, 6], [7, 8, 9], [7, 9, 10], [7, 10, 11]]


def test_an_unskinned_mesh_in_millimetres_states_its_units(tmp_path):
    path = tmp_path / "quad.usda"
    quad_stage(path, [4], [0, 1, 2, 3], [[0, 0, 0], [100, 0, 0], [100, 100, 0], [0, 100, 0]], meters_per_unit=0.001)
    character, units = read_character(path)
    assert units == "mm" and character.skeleton is None
    np.testing.assert_allclose(character.vertices.max(axis=0), [0.1, 0.1, 0.0])
    assert character.faces.tolist() == [[0, 1, 2], [0, 2, 3]]


def test_the_toy_character_keeps_bones_and_weights_through_usd(tmp_path):
    source = toy.toy_character(name="toy")
    write_scene(tmp_path / "toy.usdc", source, meters_per_unit=0.001)
    body = load_character(tmp_path / "toy.usdc")
    np.testing.assert_allclose(body.vertices, source.vertices @ Y_UP_TO_Z_UP, atol=1e-6)
    assert body.skeleton.names == source.skeleton.names
    np.testing.assert_array_equal(body.skeleton.parents, source.skeleton.parents)
    assert abs(body.weights - source.weights).max() < 1e-6


def test_bad_usd_characters_get_one_clear_error_each(tmp_path):
    (tmp_path / "junk.usda").write_bytes(b"#usda 1.0\n( this is not usd")
    expect("bad_header", tmp_path / "junk.usda")
    stage = Usd.Stage.CreateNew(str(tmp_path / "empty.usda"))
    UsdGeom.Xform.Define(stage, "/nothing")
    stage.GetRootLayer().Save()
    expect("empty_mesh", tmp_path / "empty.usda")
    quad_stage(tmp_path / "corners.usda", [4], [0, 1, 2], [[0, 0, 0], [1, 0, 0], [1, 1, 0]])
    assert "faceVertexCounts add up to 4" in str(expect("bad_faces", tmp_path / "corners.usda"))
    quad_stage(tmp_path / "index.usda", [3], [0, 1, 7], [[0, 0, 0], [1, 0, 0], [1, 1, 0]])
    expect("bad_faces", tmp_path / "index.usda")
    quad_stage(tmp_path / "furlong.usda", [3], [0, 1, 2], [[0, 0, 0], [1, 0, 0], [1, 1, 0]], meters_per_unit=201.2)
    assert "metersPerUnit 201.2" in str(expect("bad_header", tmp_path / "furlong.usda"))
    quad_stage(tmp_path / "big.usda", [3] * 4, list(range(3)) * 4, [[0, 0, 0], [1, 0, 0], [1, 1, 0]])
    expect("too_large", tmp_path / "big.usda", max_faces=2)
    quad_stage(tmp_path / "nan.usda", [3], [0, 1, 2], [[0, 0, 0], [np.nan, 0, 0], [1, 1, 0]])
    expect("non_finite", tmp_path / "nan.usda")
    data = (tmp_path / "two.usdc")
    write_scene(data, toy.toy_character(name="toy"))
    (tmp_path / "cut.usdc").write_bytes(data.read_bytes()[:400])
    expect("bad_header", tmp_path / "cut.usdc")
    expect("bad_mesh", data, mesh_name="nobody")
