"""Tests for solver/synthetic/makehuman/cache.py: the .npz caches of parsed assets."""

from __future__ import annotations

import os
import stat

import numpy as np
import pytest

from hairport.solver.synthetic.makehuman.cache import CACHE_FORMAT, FORMAT_KEY, load_cache, save_cache


def test_round_trip(tmp_path):
    path = tmp_path / "parsed" / "x.npz"  # the folder is created
    save_cache(path, {"a": np.arange(3), "b": np.array(["x", "yz"])})
    arrays = load_cache(path)
    assert set(arrays) == {FORMAT_KEY, "a", "b"} and int(arrays[FORMAT_KEY]) == CACHE_FORMAT
    np.testing.assert_array_equal(arrays["a"], [0, 1, 2])
    assert arrays["b"].tolist() == ["x", "yz"]
    assert [p.name for p in path.parent.iterdir()] == ["x.npz"]  # no temporary file left


def test_missing_unreadable_or_other_format_is_no_cache(tmp_path):
    assert load_cache(tmp_path / "none.npz") is None
    (tmp_path / "junk.npz").write_bytes(b"not a zip")
    assert load_cache(tmp_path / "junk.npz") is None
    np.savez(tmp_path / "old.npz", **{FORMAT_KEY: np.int64(CACHE_FORMAT + 1), "a": np.zeros(2)})
    assert load_cache(tmp_path / "old.npz") is None
    np.savez(tmp_path / "bare.npz", a=np.zeros(2))
    assert load_cache(tmp_path / "bare.npz") is None


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_a_read_only_folder_is_skipped(tmp_path):
    tmp_path.chmod(stat.S_IRUSR | stat.S_IXUSR)
    try:
        save_cache(tmp_path / "x.npz", {"a": np.zeros(2)})  # no error
        assert not (tmp_path / "x.npz").exists()
    finally:
        tmp_path.chmod(stat.S_IRWXU)


def test_an_unwritable_path_is_skipped(tmp_path):
    (tmp_path / "file").write_text("x")
    save_cache(tmp_path / "file" / "x.npz", {"a": np.zeros(2)})  # its folder cannot be made: no error
    assert (tmp_path / "file").read_text() == "x"
