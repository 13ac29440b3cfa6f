"""Tests for solver/io/character/mesh_file.py: the checks every character reader shares."""

from __future__ import annotations

import numpy as np
import pytest

from hairport.solver.io.character.mesh_file import check_counts, check_file, check_mesh_arrays
from hairport.solver.model.errors import InputError

TRIANGLE = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
FACES = np.array([[0, 1, 2]])


def test_check_file(tmp_path):
    path = tmp_path / "mesh.obj"
    path.write_bytes(b"x" * 10)
    check_file(path, 10)  # exactly at the limit
    cases = [(tmp_path / "missing.obj", 10, "not_found"), (tmp_path, 10, "not_found"), (path, 9, "too_large")]
    for where, limit, code in cases:
        with pytest.raises(InputError) as error:
            check_file(where, limit)
        assert error.value.code == code and error.value.source == str(where)
    empty = tmp_path / "empty.obj"
    empty.write_bytes(b"")
    with pytest.raises(InputError) as error:
        check_file(empty, 10)
    assert error.value.code == "empty_mesh"


def test_check_counts():
    check_counts(5, 7, "m", 5, 7)
    with pytest.raises(InputError, match="6 vertices, more than the limit of 5") as error:
        check_counts(6, 7, "m", 5, 7)
    assert error.value.code == "too_large" and error.value.source == "m"
    with pytest.raises(InputError, match="8 faces, more than the limit of 7") as error:
        check_counts(5, 8, "m", 5, 7)
    assert error.value.code == "too_large"


@pytest.mark.parametrize(
    "vertices, faces, code, words",
    [
        (np.zeros((0, 3)), FACES, "empty_mesh", "0 vertices, 1 faces"),
        (TRIANGLE, np.zeros((0, 3), np.int64), "empty_mesh", "3 vertices, 0 faces"),
        (np.concatenate([TRIANGLE, [[0.0, np.nan, 0.0]]]), FACES, "non_finite", "vertex 3"),
        (np.concatenate([TRIANGLE, [[np.inf, 0.0, 0.0]]]), FACES, "non_finite", "vertex 3"),
        (TRIANGLE, np.array([[0, 1, 3]]), "bad_faces", "out of range"),
        (TRIANGLE, np.array([[0, -1, 2]]), "bad_faces", "out of range"),
        (np.zeros((5, 3)), FACES, "too_large", "5 vertices"),
        (TRIANGLE, np.array([[0, 1, 2], [2, 1, 0]]), "too_large", "2 faces"),
        (TRIANGLE, np.array([[0, 1, 1]]), "empty_mesh", "every face (1) has zero area"),
        (np.array([[0.0, 0, 0], [1, 1, 1], [2, 2, 2]]), FACES, "empty_mesh", "every face (1) has zero area"),
    ],
)
def test_check_mesh_arrays(vertices, faces, code, words):
    with pytest.raises(InputError) as error:
        check_mesh_arrays(vertices, faces, "body.obj", 4, 1)
    assert error.value.code == code and words in error.value.problem


def test_check_mesh_arrays_accepts_a_mesh_at_the_limits():
    check_mesh_arrays(TRIANGLE, FACES, "body.obj", 3, 1)  # no error
