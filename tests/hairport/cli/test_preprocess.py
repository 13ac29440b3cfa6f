"""``hairport preprocess``, then ``retarget --adaptable``: the artifact gives the one-shot result."""

from __future__ import annotations

import json

import numpy as np

from hairport.solver.io.hair import read_hair
from tests.hairport.cli.helpers import N_STRANDS, assert_input_error, assert_nothing_written, run


def test_preprocess_then_retarget_from_the_artifact_equals_the_one_shot_run(capsys, world, out):
    d = world["dir"]
    artifact = out / "groom.hpa"
    code, stdout, err = run(capsys, ["preprocess", "--source", str(d / "source.obj"), "--hair", str(d / "hair.data"),
                                     "--guides", "20", "--out", str(artifact), "--quiet"])
    assert code == 0, err
    assert f"{N_STRANDS} strands" in stdout and "20 guides" in stdout
    common = ["--target", str(d / "target.obj"), "--max-iterations", "5", "--workers", "1", "--quiet"]
    code, _, err = run(capsys, ["retarget", "--adaptable", str(artifact), "--out", str(out / "a.npz"),
                                "--report", str(out / "a.json")] + common)
    assert code == 0, err
    code, _, err = run(capsys, ["retarget", "--source", str(d / "source.obj"), "--hair", str(d / "hair.data"),
                                "--guides", "20", "--out", str(out / "b.npz")] + common)
    assert code == 0, err
    a, b = read_hair(out / "a.npz"), read_hair(out / "b.npz")
    assert np.array_equal(a.points, b.points)
    report = json.loads((out / "a.json").read_text())
    assert report["metrics"]["method"] == "multiscale"  # the default
    assert report["inputs"]["guides"] == 20 and report["inputs"]["adaptable"] == str(artifact)
    assert report["metrics"]["penetrating_particles"] == 0
    for stage in ("coarse_solve", "fine_solve", "initial_transfer"):
        assert report["timings_s"][stage] >= 0
    assert report["solver"]["guides"] == 20


def test_adaptable_and_source_together_are_refused(capsys, world, out):
    d = world["dir"]
    code, _, err = run(capsys, ["retarget", "--adaptable", str(d / "x.hpa"), "--hair", str(d / "hair.data"),
                                "--target", str(d / "target.obj"), "--out", str(out / "r.data"), "--quiet"])
    assert_input_error(code, err, "--adaptable", "not both")
    assert_nothing_written(out)


def test_retarget_without_any_source_is_refused(capsys, world, out):
    d = world["dir"]
    code, _, err = run(capsys, ["retarget", "--target", str(d / "target.obj"), "--out", str(out / "r.data"), "--quiet"])
    assert_input_error(code, err, "--adaptable", "--source")


def test_corrupted_artifact_is_one_line_error(capsys, world, out, tmp_path):
    bad = tmp_path / "bad.hpa"
    bad.write_bytes(b"PK\x03\x04 not really a zip")
    code, _, err = run(capsys, ["retarget", "--adaptable", str(bad), "--target", str(world["dir"] / "target.obj"),
                                "--out", str(out / "r.data"), "--quiet"])
    assert_input_error(code, err, str(bad), "adaptable hairstyle")
    assert_nothing_written(out)


def test_preprocess_refuses_a_wrong_extension_and_zero_guides(capsys, world, out):
    d = world["dir"]
    base = ["preprocess", "--source", str(d / "source.obj"), "--hair", str(d / "hair.data"), "--quiet"]
    code, _, err = run(capsys, base + ["--out", str(out / "groom.npz")])
    assert_input_error(code, err, ".hpa")
    code, _, err = run(capsys, base + ["--out", str(out / "groom.hpa"), "--guides", "0"])
    assert_input_error(code, err, "guides", ">= 1")
    assert_nothing_written(out)
