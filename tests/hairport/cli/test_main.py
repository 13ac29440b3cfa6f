"""``main``: errors become one line and an exit code; the installed console script propagates it."""

from __future__ import annotations

import os
import shutil
import stat
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from hairport.cli import EXIT_BAD_INPUT, EXIT_FAILURE, build_parser, main, show_warning
from hairport.solver import read_hair
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
    assert "{preprocess,retarget,batch,demo,assets,serve,worker,warmup,purge,reindex,db,migrate,openapi,hairline,convert}" in build_parser().format_help()
    args = build_parser().parse_args(["purge"])
    assert args.run.__name__ == "cmd_purge"


#: hair files with nothing to retarget: (name, bytes, words of the one error line)
WITHOUT_HAIR = [
    ("zero.data", struct.pack("<i", 0), "no strand of two or more points"),
    ("dots.data", struct.pack("<ii3fi3f", 2, 1, 0, 1.6, 0, 1, 0.1, 1.6, 0), "no strand of two or more points"),
    ("flat.data", struct.pack("<ii6f", 1, 2, *([0.0, 1.6, 0.0] * 2)), "every strand (1) has zero length"),
    ("empty.obj", b"", "no polyline ('l') records (0 vertices)"),
    ("garbage.obj", np.random.default_rng(5).integers(1, 256, 120_000, dtype=np.uint8).tobytes(),
     "is not an OBJ record"),
]


@pytest.mark.parametrize("command", ["retarget", "preprocess"])
@pytest.mark.parametrize("name, data, words", WITHOUT_HAIR, ids=[case[0] for case in WITHOUT_HAIR])
def test_hair_without_hair_is_one_line_exit_2_and_no_output(capsys, world, out, tmp_path, command, name, data, words):
    bad = tmp_path / name
    bad.write_bytes(data)
    args = retarget_args(world, out, hair=bad)
    if command == "preprocess":
        args = ["preprocess", "--source", str(world["dir"] / "source.obj"), "--hair", str(bad),
                "--out", str(out / "groom.hpa"), "--quiet"]
    capsys.readouterr()
    code = main(args)
    captured = capsys.readouterr()
    code_name = "not_text" if name == "garbage.obj" else "empty_hair"
    line = assert_input_error(code, captured.err, str(bad), words, f"(code {code_name})")
    assert len(line) < 300 and captured.out == ""
    assert_nothing_written(out)


@pytest.mark.parametrize("which", ["--source", "--target"])
def test_a_mesh_without_faces_is_one_line_exit_2(capsys, world, out, tmp_path, which):
    bad = tmp_path / "points.obj"
    bad.write_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    args = retarget_args(world, out, **{which[2:]: bad})
    capsys.readouterr()
    code = main(args)
    assert_input_error(code, capsys.readouterr().err, str(bad), "empty mesh", "0 faces")
    assert_nothing_written(out)


def test_warnings_are_one_hairport_line_without_python_source(capsys, world, out, tmp_path):
    hair = read_hair(world["dir"] / "hair.data")
    strands = [hair.strand(s) for s in range(hair.n_strands)] + [hair.strand(0)[:1], hair.strand(1)[:1]]
    dotted = tmp_path / "dotted.data"
    dotted.write_bytes(struct.pack("<i", len(strands)) + b"".join(
        struct.pack("<i", len(s)) + s.astype("<f4").tobytes() for s in strands))
    capsys.readouterr()
    code = main(retarget_args(world, out, hair=dotted, all_outputs=False))
    err = capsys.readouterr().err
    assert code == 0, err
    assert err == (f"hairport: warning: {dotted}: skipped 2 strand(s) with fewer than 2 points (2 point(s)); "
                   "USC-HairSalon files mark scalp positions without hair this way\n")


def test_a_warning_of_several_lines_is_printed_as_one(capsys):
    show_warning("first line\n  second line", UserWarning, "/somewhere/module.py", 12, line="warnings.warn(...)")
    assert capsys.readouterr().err == "hairport: warning: first line second line\n"


def test_hair_report_and_preview_share_one_file_mode(capsys, world, out):
    previous = os.umask(0o022)
    try:
        code = main(retarget_args(world, out))
    finally:
        os.umask(previous)
    assert code == 0, capsys.readouterr().err
    modes = {p.name: stat.S_IMODE(p.stat().st_mode) for p in out.iterdir()}
    assert modes == {"result.data": 0o644, "report.json": 0o644, "preview.png": 0o644}
