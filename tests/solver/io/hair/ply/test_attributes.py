"""Attributes as PLY properties: the types PLY holds, the names an attribute takes, runs joined on reading."""

import numpy as np

from hairport.solver.io.hair.common import Strands
from hairport.solver.io.hair.ply.attributes import ply_dtype, property_names, read_attributes
from hairport.solver.model.hair import HairAttribute


def test_ply_types_and_exact_narrowing():
    assert ply_dtype(np.zeros(2, np.float32)) == np.float32
    assert ply_dtype(np.zeros(2, bool)) == np.uint8
    assert ply_dtype(np.array([1, -2**31], np.int64)) == np.int32
    assert ply_dtype(np.array([2**31], np.int64)) is None
    assert property_names("uv", HairAttribute(np.zeros((3, 2)), "vertex")) == ["uv_0", "uv_1"]


def test_runs_are_joined_only_when_whole_and_of_one_type():
    element = {"a_0": np.zeros(2, np.float32), "a_1": np.ones(2, np.float32),
               "b_0": np.zeros(2, np.float32), "b_1": np.ones(2, np.float64),  # two types: kept apart
               "c": np.zeros(2), "c_0": np.ones(2), "c_1": np.ones(2),  # 'c' exists: the run is not 'c'
               "lone_0": np.arange(2)}
    found = Strands(np.zeros((2, 3)), np.array([2]))
    read_attributes(element, set(), "vertex", None, found)
    assert list(found.attributes) == ["a", "b_0", "b_1", "c", "c_0", "c_1", "lone_0"]
    assert found.attributes["a"].values.tolist() == [[0, 1], [0, 1]]
