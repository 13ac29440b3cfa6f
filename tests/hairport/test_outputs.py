"""All-or-nothing output files."""

import json
import os
import stat

import numpy as np
import pytest

from hairport.outputs import OutputSet, json_default
from hairport.solver import FILE_MODE, atomic_write_bytes


def test_files_appear_only_on_commit(tmp_path):
    with OutputSet() as outputs:
        outputs.add(tmp_path / "a" / "hair.data", lambda path: path.write_bytes(b"1234"))
        outputs.add_json(tmp_path / "report.json", {"n": np.int64(3), "v": np.array([1.5, 2.0])})
        assert sorted(p.name for p in tmp_path.rglob("*") if p.is_file() and not p.name.startswith(".")) == []
        written = outputs.commit()
    assert [p.name for p in written] == ["hair.data", "report.json"]
    assert (tmp_path / "a" / "hair.data").read_bytes() == b"1234"
    assert json.loads((tmp_path / "report.json").read_text()) == {"n": 3, "v": [1.5, 2.0]}
    assert [p.name for p in tmp_path.rglob(".*")] == []


def test_a_failure_leaves_nothing(tmp_path):
    def broken(path):
        path.write_bytes(b"half")
        raise OSError("disk full")

    with pytest.raises(OSError):
        with OutputSet() as outputs:
            outputs.add(tmp_path / "first.data", lambda path: path.write_bytes(b"ok"))
            outputs.add(tmp_path / "second.data", broken)
    assert list(tmp_path.iterdir()) == []


def test_temporary_names_keep_the_extension(tmp_path):
    seen = []
    with OutputSet() as outputs:
        outputs.add(tmp_path / "x.ply", lambda path: seen.append(path.suffix) or path.write_text(""))
        outputs.abort()
    assert seen == [".ply"] and list(tmp_path.iterdir()) == []


def test_json_default_refuses_other_objects():
    assert json_default(np.float32(0.5)) == 0.5
    with pytest.raises(TypeError, match="not JSON serialisable: object"):
        json_default(object())


@pytest.fixture
def umask():
    """Set the process umask for a test (``umask(value)``), restored afterwards."""
    old = os.umask(0o022)
    try:
        yield os.umask
    finally:
        os.umask(old)


@pytest.mark.parametrize("mask, mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_every_output_has_the_file_mode_less_the_umask(tmp_path, umask, mask, mode):
    umask(mask)
    with OutputSet() as outputs:
        outputs.add(tmp_path / "preview.png", lambda path: path.write_bytes(b"png"))  # writes into the temporary
        outputs.add_json(tmp_path / "report.json", {"n": 1})
        outputs.add(tmp_path / "hair.data", lambda path: atomic_write_bytes(path, b"hair"))  # replaces it
        written = outputs.commit()
    assert FILE_MODE & ~mask == mode
    assert {p.name: stat.S_IMODE(p.stat().st_mode) for p in written} == dict.fromkeys(
        ["preview.png", "report.json", "hair.data"], mode)
