"""Hairline edits on the command line (MakeHuman characters: the toy groom does not reach the ears)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from hairport import cli, solver
from hairport.solver.io.hair import write_hair
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import write_character
from tests.hairport.cli.helpers import assert_input_error, assert_nothing_written, call_log, run


@pytest.fixture(scope="module")
def human_world(tmp_path_factory) -> dict:
    from hairport.solver.synthetic.makehuman import PRESETS, build_character

    d = tmp_path_factory.mktemp("cli-human")
    for name in ("average-female", "heavy-male"):
        character = build_character(PRESETS[name])
        write_character(character, d / f"{name}.obj", d / f"{name}.skeleton.json")
        if name == "average-female":
            write_hair(d / "short.data", generate_groom(character, "short", 80, 6, seed=2))
    code = cli.main(["preprocess", "--source", str(d / "average-female.obj"), "--hair", str(d / "short.data"),
                     "--guides", "20", "--out", str(d / "short.hpa"), "--quiet"])
    assert code == 0
    return {"dir": d, "adaptable": d / "short.hpa", "target": d / "heavy-male.obj"}


def hairline_args(world, out: Path, *extra: str) -> list[str]:
    return ["retarget", "--adaptable", str(world["adaptable"]), "--target", str(world["target"]),
            "--out", str(out / "result.npz"), "--report", str(out / "report.json"), "--max-iterations", "8",
            "--workers", "1", "--quiet", *extra]


def test_hairline_preset_on_the_command_line(capsys, human_world, out):
    code, stdout, err = run(capsys, hairline_args(human_world, out, "--hairline", "widows-peak:0.6"))
    assert code == 0, err
    assert "hairline widows-peak:0.6 (membrane)" in stdout and "density change L1" in stdout
    report = json.loads((out / "report.json").read_text())
    hairline = report["metrics"]["hairline"]
    assert hairline["edit"] == "widows-peak:0.6" and hairline["roots_moved"] > 0
    assert report["metrics"]["penetrating_particles"] == 0 and report["timings_s"]["hairline"] > 0


def test_current_hairline_round_trips_as_a_curve(capsys, human_world, out, tmp_path):
    curve = tmp_path / "current.json"
    code, stdout, err = run(capsys, ["hairline", "--adaptable", str(human_world["adaptable"]), "--target",
                                     str(human_world["target"]), "--out", str(curve), "--quiet"])
    assert code == 0, err
    document = json.loads(curve.read_text())
    assert document["units"] == "m" and len(document["points"]) > 20 and document["turning_points"][0] == 0
    code, _, err = run(capsys, hairline_args(human_world, out, "--hairline-curve", str(curve)))
    assert code == 0, err
    hairline = json.loads((out / "report.json").read_text())["metrics"]["hairline"]
    assert hairline["max_travel_m"] < 1e-6  # the hairline as it is: nothing moves


@pytest.mark.parametrize("document, words", [
    ({"points": [[0, 1.6, 0], [0.1, 1.6, 0]]}, ["at least 3 points"]),
    ({"units": "ft", "points": [[0, 1.6, 0], [0.1, 1.6, 0], [0.2, 1.6, 0]]}, ["unknown units"]),
    ({"points": [[0, 0, 0], [0.1, 0, 0], [0.2, 0, 0]]}, ["off the head"]),
    ("not json", ["not valid json"]),
])
def test_bad_hairline_curves_are_one_line_errors(capsys, human_world, out, tmp_path, document, words):
    path = tmp_path / "curve.json"
    path.write_text(document if isinstance(document, str) else json.dumps(document))
    code, _, err = run(capsys, hairline_args(human_world, out, "--hairline-curve", str(path)))
    assert_input_error(code, err, "curve", *words)
    assert_nothing_written(out)


def test_bad_hairline_presets_are_refused_before_any_work(capsys, human_world, out, monkeypatch):
    calls = call_log(monkeypatch, solver, "retarget")
    code, _, err = run(capsys, hairline_args(human_world, out, "--hairline", "mohawk"))
    assert_input_error(code, err, "unknown hairline preset", "widows-peak")
    code, _, err = run(capsys, hairline_args(human_world, out, "--hairline", "round:2"))
    assert_input_error(code, err, "[0, 1]")
    code, _, err = run(capsys, hairline_args(human_world, out, "--hairline", "round", "--method", "global-translate"))
    assert_input_error(code, err, "baseline")
    assert calls == [] and not any(out.iterdir())
