"""The one atomic write: whole files or nothing, readable by the other processes."""

import os
import stat

import pytest

from hairport.solver.model.files import TEMP_SUFFIX, atomic_write, atomic_write_bytes


def test_the_file_appears_whole(tmp_path):
    path = tmp_path / "out.bin"
    path.write_bytes(b"old")
    assert atomic_write_bytes(path, b"new content") == path
    assert path.read_bytes() == b"new content" and sorted(os.listdir(tmp_path)) == ["out.bin"]
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(path.stat().st_mode) == 0o666 & ~umask


def test_a_failed_write_keeps_the_old_file_and_leaves_no_temporary(tmp_path):
    path = tmp_path / "out.bin"
    path.write_bytes(b"old")

    def broken(handle):
        handle.write(b"half")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        atomic_write(path, broken, durable=False)
    assert path.read_bytes() == b"old" and os.listdir(tmp_path) == ["out.bin"]


def test_temporaries_are_hidden_beside_the_destination(tmp_path):
    names = []

    def peek(handle):
        names.extend(os.listdir(tmp_path))
        handle.write(b"x")

    atomic_write(tmp_path / "a.json", peek)
    assert len(names) == 1 and names[0].startswith(".a.json.") and names[0].endswith(TEMP_SUFFIX)
