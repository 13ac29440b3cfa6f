"""``hairport demo``: the whole job on built-in MakeHuman data, written into one folder."""

import json

from hairport.cli import main
from hairport.cli.demo import TABLE_ROWS, format_table
from hairport.solver import read_hair


def test_a_small_demo_writes_every_output(tmp_path, capsys):
    out = tmp_path / "demo"
    code = main(["demo", "--out", str(out), "--strands", "40", "--particles", "8", "--hairline", "none", "--quiet"])
    assert code == 0
    assert sorted(p.name for p in out.iterdir()) == sorted([
        "source.obj", "source.skeleton.json", "target.obj", "target.skeleton.json", "source_hair.hair",
        "result_hair.hair", "report.json", "preview.png",
        next(p.name for p in out.iterdir() if p.name.startswith("baseline_")),
    ])
    report = json.loads((out / "report.json").read_text())
    assert report["result"]["metrics"]["penetrating_particles"] == 0
    assert report["demo"]["strands"] == 40 and len(report["baselines"]) == 10
    assert read_hair(out / "result_hair.hair").n_particles == 320
    printed = capsys.readouterr().out
    assert printed.splitlines()[0].split()[:2] == ["metric", "hairport"] and report["best_baseline"] in printed


def test_an_unknown_preset_is_one_line(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--source-preset", "giant", "--quiet"]) == 2
    assert capsys.readouterr().err.strip() == (
        "hairport: error: unknown preset 'giant'; expected one of average-female, average-male, heavy-male, "
        "muscular-male, slim-tall-female, child")
    assert list(tmp_path.iterdir()) == []


def test_table_lines_up_ours_and_the_baseline():
    metrics = {key: 0 if fmt == "{:d}" else 0.5 for key, _, fmt in TABLE_ROWS if "." not in key}
    metrics["segment_length_ratio_in_strand"] = {"p5": 0.125, "p50": 1.0, "p95": 2.5}
    lines = format_table(metrics, metrics, "rbf-warp").splitlines()
    assert len(lines) == 2 + len(TABLE_ROWS) and len({len(line) for line in lines}) == 1
    assert lines[2].startswith("penetrating particles") and lines[2].endswith("0")
    in_strand = [line for line in lines if line.startswith("segment length in strand")]
    assert [line.split()[-1] for line in in_strand] == ["0.125", "2.500"]
