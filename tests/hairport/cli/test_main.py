"""``main``: errors become one line and an exit code; the installed console script propagates it."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from hairport.cli import EXIT_BAD_INPUT, EXIT_FAILURE, build_parser, main
from tests.hairport.cli.helpers import assert_input_error, assert_nothing_written, retarget_args


def hairport_executable() -> str:
    beside = Path(sys.executable).with_name("hairport")
    if beside.is_file():
        return str(beside)
    found = shutil.which("hairport")
    if found is None:
        pytest.skip("the hairport console script is not installed")
    return found


@pytest.mark.integration  # a subprocess of the installed console script
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


def test_missing_files_and_write_failures_are_one_line(world, tmp_path, capsys):
    code = main(["retarget", "--source", str(tmp_path / "nowhere.obj"), "--hair", str(world["dir"] / "hair.data"),
                 "--target", str(world["dir"] / "target.obj"), "--out", str(tmp_path / "out.data"), "--quiet"])
    err = capsys.readouterr().err
    assert code == EXIT_BAD_INPUT and err == f"hairport: error: {tmp_path / 'nowhere.obj'}: file not found\n"
    blocked = tmp_path / "blocked"
    blocked.write_text("a file where a folder should be")
    code = main(["openapi", "--out", str(blocked / "api.yaml")])
    err = capsys.readouterr().err
    assert code == EXIT_FAILURE and err.startswith("hairport: error: ") and err.count("\n") == 1


def test_the_commands():
    assert "{preprocess,retarget,demo,assets,serve,worker,purge,openapi,hairline}" in build_parser().format_help()
    args = build_parser().parse_args(["purge"])
    assert args.run.__name__ == "cmd_purge"
