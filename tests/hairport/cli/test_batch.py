"""``hairport batch``: three grooms x four toy characters give twelve folders and a summary; each pair equals
``hairport retarget`` of that pair; targets of another topology are wrapped once per wrap key (and, with the
wrap off or a target that cannot be wrapped, fail their pairs only); bad arguments write nothing."""

from __future__ import annotations

import csv
import json

import numpy as np

from hairport import cli
from hairport.solver.io.character.obj import write_obj
from hairport.solver.io.hair import read_hair, write_hair
from hairport.solver.synthetic import toy
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import write_character
from tests.hairport.cli.helpers import assert_nothing_written, run

OPTIONS = ["--max-iterations", "5", "--format", "ply", "--quiet"]


def grid_inputs(world, folder):
    """A second and third groom (one preprocessed to an artifact), and a fourth, taller target."""
    d = world["dir"]
    write_hair(folder / "curly.data", generate_groom(world["source"], "short", 30, 8, seed=5))
    write_hair(folder / "third.data", generate_groom(world["source"], "short", 20, 8, seed=7))
    assert cli.main(["preprocess", "--source", str(d / "source.obj"), "--hair", str(folder / "third.data"),
                     "--out", str(folder / "third.hpa")]) == 0
    tall = toy.toy_character(head_scale=(0.95, 1.1, 1.0), neck_length=0.13, shoulder_width=0.38, name="tall")
    write_character(tall, folder / "tall.obj", folder / "tall.skeleton.json")
    return ["--groom", str(d / "source.obj"), str(d / "hair.data"), "--groom", str(d / "source.obj"),
            str(folder / "curly.data"), "--adaptable", str(folder / "third.hpa")]


def test_a_3_by_4_grid_gives_12_folders_a_summary_and_the_single_pair_results(world, out, tmp_path, capsys):
    grooms = grid_inputs(world, tmp_path)
    d = world["dir"]
    targets = [str(d / "target.obj"), str(d / "bare.obj"), str(d / "source.obj"), str(tmp_path / "tall.obj")]
    code, stdout, _ = run(capsys, ["batch", *grooms, "--targets", *targets, "--out", str(out), *OPTIONS])
    assert code == 0 and "12 of 12 pairs retargeted" in stdout
    folders = sorted(path.name for path in out.iterdir() if path.is_dir())
    expected = sorted(f"{groom}__{target}" for groom in ("hair", "curly", "third")
                      for target in ("target", "bare", "source", "tall"))
    assert folders == expected
    rows = list(csv.DictReader((out / "summary.csv").open()))
    assert len(rows) == 12 and all(row["status"] == "ok" and row["error"] == "" for row in rows)
    summary = json.loads((out / "summary.json").read_text())["pairs"]
    assert all(pair["penetrating_particles"] == 0 and pair["root_to_target_max"] <= 1e-6 for pair in summary)
    for folder, pair, row in zip(expected, sorted(summary, key=lambda pair: pair["folder"]),
                                 sorted(rows, key=lambda row: row["folder"]), strict=True):
        strands = {"hair": 60, "curly": 30, "third": 20}[folder.split("__")[0]]
        assert read_hair(out / folder / "result.ply").n_strands == strands
        metrics = json.loads((out / folder / "report.json").read_text())["metrics"]
        assert metrics["penetrating_particles"] == 0
        # the summary's count of segments through the body is the pair's report's
        assert pair["folder"] == row["folder"] == folder
        assert pair["crossing_segments"] == metrics["crossing_segments"]["count"] == int(row["crossing_segments"])
    single = tmp_path / "single.ply"
    assert cli.main(["retarget", "--source", str(d / "source.obj"), "--hair", str(tmp_path / "curly.data"),
                     "--target", str(d / "bare.obj"), "--out", str(single), "--max-iterations", "5", "--quiet"]) == 0
    np.testing.assert_array_equal(read_hair(single).points, read_hair(out / "curly__bare" / "result.ply").points)


def test_a_target_of_another_topology_with_the_wrap_off_fails_its_pairs_only(world, out, tmp_path, capsys):
    d = world["dir"]
    target = world["target"]
    write_obj(tmp_path / "broken.obj", target.vertices, target.faces[:-3], "three faces short")
    code, stdout, err = run(capsys, ["batch", "--groom", str(d / "source.obj"), str(d / "hair.data"),
                                     "--targets", str(d / "target.obj"), str(tmp_path / "broken.obj"),
                                     "--out", str(out), "--wrap", "off", *OPTIONS])
    assert code == 2 and "1 of 2 pairs retargeted" in stdout
    assert "hair x broken" in err and "topology" in err and "--wrap off" in err
    rows = {row["target"]: row for row in csv.DictReader((out / "summary.csv").open())}
    assert rows["target"]["status"] == "ok" and rows["broken"]["status"] == "failed"
    assert "faces" in rows["broken"]["error"] or "topology" in rows["broken"]["error"]
    assert not (out / "hair__broken").exists() and (out / "hair__target" / "result.ply").is_file()


def test_targets_of_another_topology_are_wrapped_once_per_wrap_and_a_sphere_fails_alone(remeshed_world, out,
                                                                                       tmp_path, capsys):
    """Two artifacts of one groom (20 and 10 guides: the same bodies and reach, so one wrap key) onto the remeshed
    male, his head in mm with Z up, and a sphere: each target is wrapped for the first groom and the wrap reused
    for the second, each result is the one ``hairport retarget`` gives the pair alone; the sphere's pairs fail
    with the wrap's refusal, the other pairs do not."""
    d = remeshed_world["dir"]
    code, stdout, err = run(capsys, [
        "batch", "--adaptable", str(d / "short20.hpa"), str(d / "short10.hpa"), "--targets", str(d / "male.obj"),
        str(d / "head.obj"), str(d / "sphere.obj"), "--out", str(out), "--max-iterations", "5", "--quiet"])
    assert code == 2 and "4 of 6 pairs retargeted" in stdout
    rows = {(row["groom"], row["target"]): row for row in csv.DictReader((out / "summary.csv").open())}
    for target in ("male", "head"):
        assert (rows["short20", target]["wrap"], rows["short10", target]["wrap"]) == ("wrapped", "reused")
        assert rows["short20", target]["penetrating_particles"] == rows["short10", target]["penetrating_particles"] == "0"
        # a reused wrap costs nothing: the second groom's pair takes a fraction of the first's
        assert float(rows["short10", target]["seconds"]) < 0.6 * float(rows["short20", target]["seconds"])
    for groom in ("short20", "short10"):
        assert rows[groom, "sphere"]["status"] == "failed" and "could not be wrapped" in rows[groom, "sphere"]["error"]
        assert f"{groom} x sphere: " in err and not (out / f"{groom}__sphere").exists()
    report = json.loads((out / "short10__head" / "report.json").read_text())
    assert report["metrics"]["wrap"] == json.loads((out / "short20__head" / "report.json").read_text())["metrics"]["wrap"]
    assert "wrap" not in report["timings_s"] and report["metrics"]["input"]["target"]["units"] == "mm"
    single = tmp_path / "single.npz"
    assert cli.main(["retarget", "--adaptable", str(d / "short10.hpa"), "--target", str(d / "head.obj"),
                     "--out", str(single), "--max-iterations", "5", "--quiet"]) == 0
    np.testing.assert_array_equal(read_hair(single).points, read_hair(out / "short10__head" / "result.npz").points)


def test_bad_arguments_write_nothing(world, out, capsys):
    d = world["dir"]
    code, _, err = run(capsys, ["batch", "--targets", str(d / "target.obj"), "--out", str(out)])
    assert code == 2 and "at least one groom" in err
    code, _, err = run(capsys, ["batch", "--groom", str(d / "source.obj"), str(d / "hair.data"), "--targets",
                                str(d / "target.obj"), "--out", str(out), "--max-iterations", "0"])
    assert code == 2 and "max_iterations" in err
    code, _, err = run(capsys, ["batch", "--groom", str(d / "source.obj"), str(d / "missing.data"), "--targets",
                                str(d / "target.obj"), "--out", str(out)])
    assert code == 2 and "missing.data" in err
    assert_nothing_written(out)
