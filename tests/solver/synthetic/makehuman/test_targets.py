"""Tests for solver/synthetic/makehuman/targets.py: target files, parsed per folder and cached."""

from __future__ import annotations

import gzip

import numpy as np
import pytest

from hairport.solver.model.errors import InputError
from hairport.solver.synthetic.makehuman.base_model import N_FULL_VERTICES
from hairport.solver.synthetic.makehuman.cache import PARSED_DIR
from hairport.solver.synthetic.makehuman.targets import (
    TARGET_DELTA_SCALE,
    TargetGroup,
    read_target_file,
    target_files,
    target_name,
)


def write_target(path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with gzip.open(path, "wt") as handle:
        handle.write(text)


def test_read_target_file(tmp_path):
    path = tmp_path / "a.target.gz"
    write_target(path, "# a comment\n5 0.1 -0.2 0.003\n2 1 2 3\n5 0.1 0 0\n")
    indices, deltas = read_target_file(path)
    np.testing.assert_array_equal(indices, [2, 5])  # repeated lines are summed, indices sorted
    np.testing.assert_allclose(deltas, [[1, 2, 3], [0.2, -0.2, 0.003]], rtol=1e-15)
    write_target(path, "# only comments\n\n")
    indices, deltas = read_target_file(path)
    assert indices.shape == (0,) and deltas.shape == (0, 3)


@pytest.mark.parametrize(
    "text, words",
    [("1 0.1 0.2\n", "expected 4 columns"), (f"{N_FULL_VERTICES} 0 0 0\n", "out of range"),
     ("-1 0 0 0\n", "out of range"), ("1.5 0 0 0\n", "out of range")],
)
def test_bad_target_files(tmp_path, text, words):
    path = tmp_path / "bad.target.gz"
    write_target(path, text)
    with pytest.raises(InputError) as error:
        read_target_file(path)
    assert error.value.code == "bad_target" and words in error.value.problem and error.value.source == str(path)


def test_names_of_the_files(tmp_path):
    for stem in ("b", "a-b", "a"):
        write_target(tmp_path / "targets" / "head" / f"{stem}.target.gz", "1 0 0 0\n")
    files = target_files(tmp_path, "head")
    assert [p.name for p in files] == ["a-b.target.gz", "a.target.gz", "b.target.gz"]  # sorted by path
    assert [target_name("head", p) for p in files] == ["head/a-b", "head/a", "head/b"]


def test_group_quantises_exactly_and_caches(tmp_path):
    folder = tmp_path / "targets" / "neck"
    write_target(folder / "thin.target.gz", "3 0.125 -1.5 0.001\n7 2 0 0\n")
    write_target(folder / "empty.target.gz", "# nothing\n")
    group = TargetGroup(tmp_path, "neck")
    assert group.names == ("neck/empty", "neck/thin") and group.quantized
    assert group.deltas.dtype == np.int16 and group.indices.dtype == np.uint16
    np.testing.assert_array_equal(group.deltas, [[125, -1500, 1], [2000, 0, 0]])
    assert (tmp_path / PARSED_DIR / "targets-neck.npz").is_file()
    out = np.zeros((10, 3))
    group.add_to(out, "neck/thin", 0.5)
    group.add_to(out, "neck/empty", 1.0)
    expected = np.zeros((10, 3))
    expected[3] = [0.0625, -0.75, 0.0005]
    expected[7] = [1.0, 0.0, 0.0]
    np.testing.assert_array_equal(out, expected)  # the integers divided back give the parsed doubles
    assert "neck/thin" in group and "neck/fat" not in group
    # a second group reads the cache: same arrays
    again = TargetGroup(tmp_path, "neck")
    np.testing.assert_array_equal(again.deltas, group.deltas)
    np.testing.assert_array_equal(again.offsets, [0, 0, 2])


def test_group_keeps_doubles_that_do_not_quantise(tmp_path):
    write_target(tmp_path / "targets" / "ears" / "fine.target.gz", "1 0.00015 0 0\n")
    group = TargetGroup(tmp_path, "ears")
    assert not group.quantized and group.deltas.dtype == np.float64
    out = np.zeros((2, 3))
    group.add_to(out, "ears/fine", 1.0)
    assert out[1, 0] == 0.00015 and TARGET_DELTA_SCALE * 0.00015 != round(TARGET_DELTA_SCALE * 0.00015)
