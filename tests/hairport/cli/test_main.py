"""The installed ``hairport`` console script: exit codes propagate."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests.hairport.cli.helpers import assert_input_error, assert_nothing_written, retarget_args

# a subprocess of the installed console script
pytestmark = pytest.mark.integration


def hairport_executable() -> str:
    beside = Path(sys.executable).with_name("hairport")
    if beside.is_file():
        return str(beside)
    found = shutil.which("hairport")
    if found is None:
        pytest.skip("the hairport console script is not installed")
    return found


def test_console_script_propagates_exit_code(world, out, tmp_path):
    bad = tmp_path / "cut.data"
    data = (world["dir"] / "hair.data").read_bytes()
    bad.write_bytes(data[: len(data) // 2])
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    done = subprocess.run(
        [hairport_executable(), *retarget_args(world, out, hair=bad)],
        capture_output=True, text=True, timeout=120, env=env,
    )
    assert done.returncode == 2, done.stderr
    assert done.stdout == ""
    assert_input_error(done.returncode, done.stderr, str(bad), "past the end of the file")
    assert_nothing_written(out)
