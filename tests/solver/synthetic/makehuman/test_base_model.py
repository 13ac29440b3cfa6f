"""Tests for solver/synthetic/makehuman/base_model.py: the base mesh, rig and weights, parsed."""

from __future__ import annotations

import numpy as np
import pytest

from hairport.solver.model.errors import InputError
from hairport.solver.synthetic.makehuman.base_model import (
    N_FULL_VERTICES,
    base_model_from_arrays,
    joint_vertex_rows,
    parents_first,
    parse_base_model,
    split_quads,
)

N_BODY_VERTICES = 13380
N_BODY_TRIANGLES = 26756
N_GAME_ENGINE_BONES = 53


def test_quads_split_along_the_shorter_diagonal():
    # quad 0 is longer from a to c, quad 1 from b to d
    vertices = np.array([[0, 0, 0], [1, 0, 0], [3, 1, 0], [0, 1, 0], [1, 1, 0], [-2, 1, 0]], dtype=float)
    quads = np.array([[0, 1, 2, 3], [0, 1, 4, 5]])
    np.testing.assert_array_equal(split_quads(quads, vertices), [[0, 1, 3], [1, 2, 3], [0, 1, 4], [0, 4, 5]])


def test_bones_are_ordered_parents_first():
    parent_of = {"hand": "arm", "arm": "root", "root": "", "head": "root"}
    assert parents_first(["hand", "arm", "root", "head"], parent_of) == ["root", "arm", "hand", "head"]
    with pytest.raises(InputError, match="unknown parent 'hip'"):
        parents_first(["a"], {"a": "hip"})
    with pytest.raises(InputError, match="cycle") as error:
        parents_first(["a", "b", "r"], {"a": "b", "b": "a", "r": ""})
    assert error.value.code == "bad_skeleton"


def test_joint_strategies():
    groups = {"joint-neck": np.array([4, 5, 6])}
    cube = joint_vertex_rows({"strategy": "CUBE", "cube_name": "joint-neck"}, groups, "neck head")
    mean = joint_vertex_rows({"strategy": "MEAN", "vertex_indices": [1, 2]}, groups, "x")
    vertex = joint_vertex_rows({"strategy": "VERTEX", "vertex_index": 9}, groups, "x")
    xyz = joint_vertex_rows({"strategy": "XYZ", "vertex_indices": [1, 2, 3]}, groups, "x")
    assert [r.tolist() for r in cube] == [[4, 5, 6]] * 3
    assert [r.tolist() for r in mean] == [[1, 2]] * 3
    assert [r.tolist() for r in vertex] == [[9]] * 3
    assert [r.tolist() for r in xyz] == [[1], [3], [2]]  # Blender's y is the mesh's -z, Blender's z its y
    for end, words in [({"strategy": "CUBE", "cube_name": "joint-hip"}, "unknown joint cube"),
                       ({"strategy": "HEAD"}, "unsupported joint strategy"),
                       ({"strategy": "VERTEX", "vertex_index": N_FULL_VERTICES}, "out of range"),
                       ({"strategy": "VERTEX", "vertex_index": 1, "offset": [0, 1, 0]}, "offsets are not supported")]:
        with pytest.raises(InputError, match=words):
            joint_vertex_rows(end, groups, "x")


def test_weights_lose_negative_entries_and_are_normalised():
    arrays = {
        "vertices": np.zeros((N_FULL_VERTICES, 3)), "body_vertices": np.arange(3), "triangles": np.array([[0, 1, 2]]),
        "bone_names": np.array(["a", "b"]), "parents": np.array([-1, 0]),
        "w_rows": np.array([0, 0, 1, 1, 1]), "w_cols": np.array([0, 1, 0, 1, 1]), "w_vals": np.array([1.0, 3.0, -2.0, 1.0, 1.0]),
        **{f"reg{k}_{name}": value for k in range(3)
           for name, value in (("indptr", np.array([0, 1, 2, 3, 4])), ("indices", np.array([0, 1, 2, 3])),
                               ("data", np.ones(4)))},
    }
    model = base_model_from_arrays(arrays)
    np.testing.assert_array_equal(model.weights.toarray(), [[0.25, 0.75], [0.0, 1.0], [0.0, 0.0]])
    assert model.bone_names == ("a", "b") and model.joint_regressor[0].shape == (4, N_FULL_VERTICES)


def test_parsed_game_engine_rig(assets):
    arrays = parse_base_model(assets)
    model = base_model_from_arrays(arrays)
    assert model.vertices.shape == (N_FULL_VERTICES, 3)
    assert model.body_vertices.shape == (N_BODY_VERTICES,) and model.triangles.shape == (N_BODY_TRIANGLES, 3)
    assert model.triangles.min() == 0 and model.triangles.max() == N_BODY_VERTICES - 1
    assert len(model.bone_names) == N_GAME_ENGINE_BONES and model.bone_names[0] == "Root"
    assert all(model.parents[b] < b for b in range(N_GAME_ENGINE_BONES))
    for regressor in model.joint_regressor:  # every joint is a mean of vertices
        assert regressor.shape == (2 * N_GAME_ENGINE_BONES, N_FULL_VERTICES)
        np.testing.assert_allclose(np.asarray(regressor.sum(axis=1)).ravel(), 1.0, rtol=1e-14)
