"""What the commands share: progress lines, units of meshes, the source arguments, and loading inputs
in any units and axes (results written back in them)."""

import argparse
import json

import numpy as np
import pytest

from hairport.cli.common import StageProgress, check_source_arguments, mesh_units
from hairport.solver import InputError
from hairport.solver.io.character import load_character, write_character
from hairport.solver.io.hair import read_hair, write_hair
from hairport.solver.model.frame import InputFrame
from hairport.solver.synthetic import toy
from hairport.solver.synthetic.groom import generate_groom
from tests.hairport.cli.helpers import assert_input_error, assert_nothing_written, run
from tests.solver.frames import character_in, hair_in


def test_progress_lines(capsys):
    StageProgress()("solve", 0.5, "iteration 3")
    StageProgress(quiet=True)("solve", 0.5, "not printed")
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "solve" in err and " 50.0%  iteration 3" in err and err.startswith("[")


def test_units_apply_to_meshes_without_a_sidecar(tmp_path):
    args = argparse.Namespace(units="cm")
    (tmp_path / "with.obj").write_text("")
    (tmp_path / "with.skeleton.json").write_text("{}")
    (tmp_path / "bare.obj").write_text("")
    assert mesh_units(args, str(tmp_path / "bare.obj"), None) == "cm"
    assert mesh_units(args, str(tmp_path / "with.obj"), None) is None
    assert mesh_units(args, str(tmp_path / "bare.obj"), str(tmp_path / "given.json")) is None


@pytest.mark.parametrize("given, words", [
    (dict(adaptable="a.hpa", source="s.obj"), "not both"),
    (dict(adaptable="a.hpa", guides=10), "not both"),
    (dict(adaptable="a.hpa", prim="/groom/hair"), "not both"),
    (dict(source="s.obj"), "give --adaptable, or --source with --hair"),
    (dict(), "give --adaptable, or --source with --hair"),
])
def test_source_arguments(given, words):
    args = argparse.Namespace(**{"adaptable": None, "source": None, "hair": None, "source_skeleton": None,
                                 "guides": None, "prim": None, **given})
    with pytest.raises(InputError, match=words) as refused:
        check_source_arguments(args)
    assert refused.value.code == "bad_option"


# --- inputs in other units and axes (issue 11): read in any frame, results written back in it ---

def write_in_frame(d, name: str, character, frame, *, state_units: bool) -> None:
    """OBJ + sidecar of a canonical character in ``frame``; the sidecar states no units unless asked."""
    write_character(character_in(frame, character), d / f"{name}.obj", d / f"{name}.skeleton.json")
    sidecar = d / f"{name}.skeleton.json"
    document = json.loads(sidecar.read_text())
    if state_units:
        document["units"] = frame.units
    else:
        del document["units"]
    sidecar.write_text(json.dumps(document))


def write_npz_without_units(path, hair) -> None:
    """A hairport archive that records no units (float64: the meter and millimetre files hold the same
    numbers to the last bit but for the factor, which float32 formats would not)."""
    np.savez(path, format=np.array("hairport-hair"), version=np.array(1), points=hair.points, offsets=hair.offsets)


@pytest.fixture(scope="module")
def mm_world(tmp_path_factory) -> dict:
    """The toy pair and a groom in meters with their units stated, and in millimetres with none."""
    d = tmp_path_factory.mktemp("cli-mm")
    source = toy.toy_character(name="source")
    target = toy.toy_character(head_scale=(1.1, 0.95, 1.05), neck_radius=0.065, shoulder_width=0.44,
                               neck_length=0.11, name="target")
    hair = generate_groom(source, "short", 50, 8, seed=0)
    for name, character in (("source", source), ("target", target)):
        write_in_frame(d, name, character, InputFrame("m"), state_units=True)
        read_back = load_character(d / f"{name}.obj")  # the numbers the meter files hold
        write_in_frame(d, f"{name}_mm", read_back, InputFrame("mm"), state_units=False)
    write_hair(d / "hair.npz", hair)
    write_npz_without_units(d / "hair_mm.npz", hair_in(InputFrame("mm"), hair))
    # the source in meters, its sidecar stating no units (a file from another tool)
    write_in_frame(d, "source_m_bare", load_character(d / "source.obj"), InputFrame("m"), state_units=False)
    return {"dir": d}


def frame_retarget(d, out, source: str, hair: str, target: str, name: str, *extra: str) -> list[str]:
    return ["retarget", "--source", str(d / source), "--hair", str(d / hair), "--target", str(d / target),
            "--out", str(out / name), "--report", str(out / f"{name}.json"), "--workers", "1", "--quiet", *extra]


def test_millimetre_files_without_units_retarget_as_the_meter_files(capsys, mm_world, out):
    d = mm_world["dir"]
    code, _, err = run(capsys, frame_retarget(d, out, "source.obj", "hair.npz", "target.obj", "m.npz"))
    assert code == 0, err
    code, _, err = run(capsys, frame_retarget(d, out, "source_mm.obj", "hair_mm.npz", "target_mm.obj", "mm.npz"))
    assert code == 0, err
    assert err == ""  # --quiet: the inferred units are a progress line; a clean groom gives no warning
    meters = read_hair(out / "m.npz")
    millimetres = read_hair(out / "mm.npz", units="mm")  # written back in the groom's units, which it records
    difference = np.abs(millimetres.points - meters.points).max()
    assert difference < 1e-14, f"the millimetre run differs from the meter run by {difference:.3g} m"
    section = json.loads((out / "mm.npz.json").read_text())["metrics"]["input"]
    assert section["units"]["hair"] == section["units"]["source"] == section["target"]["units"] == "mm"
    assert section["units"]["how"].startswith("inferred from sizes: in mm the body is 0.61 m")
    assert section["bounding_boxes"]["source"]["units"] == "mm" and section["bounding_boxes"]["source"]["max"][1] > 1700
    report = json.loads((out / "mm.npz.json").read_text())
    assert report["inputs"]["units"] == "mm"


def test_without_quiet_the_inferred_units_and_axes_are_one_progress_line(capsys, mm_world, out):
    d = mm_world["dir"]
    args = frame_retarget(d, out, "source_mm.obj", "hair_mm.npz", "target_mm.obj", "mm.data")
    args.remove("--quiet")
    code, _, err = run(capsys, args)
    assert code == 0, err
    lines = [line for line in err.splitlines() if " input " in line]
    assert len(lines) == 2 and all(line.startswith("[") for line in lines), err
    assert "input: units mm (inferred from sizes: in mm the body is 0.61 m" in lines[0]
    assert "up +y (the head bone), front +z" in lines[0]
    assert "target: units mm (inferred: the source's size); up +y, front +z" in lines[1]


def test_hair_in_millimetres_on_a_body_in_meters_is_refused_naming_the_units(capsys, mm_world, out):
    d = mm_world["dir"]
    args = frame_retarget(d, out, "source_m_bare.obj", "hair_mm.npz", "target.obj", "x.data")
    code, _, err = run(capsys, args)
    line = assert_input_error(code, err, "units", "with the hair in mm and the body in m they sit on it",
                              "--hair-units mm --units m")
    assert "source_m_bare.obj" in line
    assert_nothing_written(out)
    # following the advice works
    code, _, err = run(capsys, args + ["--hair-units", "mm", "--units", "m"])
    assert code == 0, err
    assert 1500 < np.abs(read_hair(out / "x.data").points).max() < 2000  # written in the hair's units, mm


#: the frames of the rotated MakeHuman files: Y up (hairport's own), Blender's Z up, and X up
ROTATED = {"y-up": InputFrame(), "z-up": InputFrame(up="z", front="-y"), "x-up": InputFrame(up="x", front="z")}


@pytest.fixture(scope="module")
def rotated_world(tmp_path_factory) -> dict:
    """A rigged MakeHuman pair and a groom in three frames, retargeted once each with a preview."""
    from hairport.solver.synthetic.makehuman import PRESETS, build_character

    d = tmp_path_factory.mktemp("cli-rotated")
    source, target = (build_character(PRESETS[name], name=name) for name in ("average-female", "heavy-male"))
    hair = generate_groom(source, "short", 60, 6, seed=3)
    runs = {}
    for tag, frame in ROTATED.items():
        write_in_frame(d, f"source-{tag}", source, frame, state_units=True)
        write_in_frame(d, f"target-{tag}", target, frame, state_units=True)
        write_hair(d / f"hair-{tag}.data", hair_in(frame, hair))
        out = d / f"out-{tag}"
        out.mkdir()
        code = main_quiet(["retarget", "--source", str(d / f"source-{tag}.obj"), "--hair", str(d / f"hair-{tag}.data"),
                           "--target", str(d / f"target-{tag}.obj"), "--out", str(out / "result.data"),
                           "--report", str(out / "report.json"), "--preview", str(out / "preview.png"),
                           "--max-iterations", "8", "--workers", "1", "--quiet"])
        assert code == 0
        runs[tag] = {"hair": read_hair(out / "result.data"), "report": json.loads((out / "report.json").read_text()),
                     "preview": out / "preview.png"}
    return {"dir": d, "runs": runs, "source": source, "hair": hair}


def main_quiet(args: list[str]) -> int:
    from hairport import cli

    return cli.main(args)


@pytest.mark.parametrize("tag", ["z-up", "x-up"])
def test_rotated_rigged_files_retarget_to_the_rotated_result(rotated_world, tag):
    runs, frame = rotated_world["runs"], ROTATED[tag]
    upright = runs["y-up"]
    # the rotation is a signed permutation of the coordinates: the result is the same to the last bit
    assert np.array_equal(runs[tag]["hair"].points, frame.axes_out(upright["hair"].points))
    metrics, reference = runs[tag]["report"]["metrics"], upright["report"]["metrics"]
    for key in ("penetrating_particles", "mean_segment_angle_rad", "interstrand_error_m", "root_to_target_max"):
        assert metrics[key] == reference[key], key
    axes = metrics["input"]["axes"]
    assert (axes["up"], axes["front"], axes["up_how"]) == (frame.up, frame.front, "the head bone")
    assert (metrics["input"]["target"]["up"], metrics["input"]["target"]["front"]) == (frame.up, frame.front)
    assert metrics["input"]["units"]["how"] == "inferred for the hair: read in m its roots sit on the body"


def panel_rows(png, view: int = 0) -> tuple[float, float, int]:
    """In the source's front view of a preview: mean row of hair pixels, mean row of body pixels, and the
    lowest body row (0 at the top of the view)."""
    from PIL import Image

    from hairport.solver.render.preview import HAIR_COLOR, TITLE_HEIGHT_PX, VIEW_SIZE_PX

    width, height = VIEW_SIZE_PX
    with Image.open(png) as image:
        pixels = np.asarray(image.convert("RGB"), dtype=np.float64)
    view_pixels = pixels[TITLE_HEIGHT_PX + 20:TITLE_HEIGHT_PX + height, view * width:(view + 1) * width]
    rows = np.arange(len(view_pixels))[:, None].repeat(width, axis=1)
    hair = np.linalg.norm(view_pixels - HAIR_COLOR, axis=2) < 40
    grey = (np.ptp(view_pixels, axis=2) < 12) & (view_pixels.mean(axis=2) > 140) & (view_pixels.mean(axis=2) < 245)
    return float(rows[hair].mean()), float(rows[grey].mean()), int(rows[grey].max()) + 20


def test_the_preview_of_a_z_up_character_shows_it_upright(rotated_world, tmp_path):
    from hairport.solver.render.preview import VIEW_SIZE_PX, render_preview

    runs = rotated_world["runs"]
    from PIL import Image

    with Image.open(runs["z-up"]["preview"]) as z_up, Image.open(runs["y-up"]["preview"]) as y_up:
        assert np.array_equal(np.asarray(z_up), np.asarray(y_up))  # drawn in hairport's frame
    hair_row, body_row, lowest = panel_rows(runs["z-up"]["preview"])
    # the hair on top of the head, the body below it, reaching the bottom of the view
    assert hair_row < body_row - 40 and lowest >= VIEW_SIZE_PX[1] - 2, (hair_row, body_row, lowest)
    # the same check on the file's own coordinates drawn as they are (the head lying on its back): fails
    frame = ROTATED["z-up"]
    raw = tmp_path / "raw.png"
    render_preview(raw, [(hair_in(frame, rotated_world["hair"]), character_in(frame, rotated_world["source"]), None,
                          "raw")])
    hair_row, body_row, lowest = panel_rows(raw)
    assert not (hair_row < body_row - 40 and lowest >= VIEW_SIZE_PX[1] - 2), (hair_row, body_row, lowest)


def test_hairline_curves_are_written_and_read_in_the_grooms_frame(capsys, rotated_world, tmp_path):
    d, frame = rotated_world["dir"], ROTATED["z-up"]
    documents = {}
    for tag in ("y-up", "z-up"):
        code, _, err = run(capsys, ["hairline", "--source", str(d / f"source-{tag}.obj"), "--hair",
                                    str(d / f"hair-{tag}.data"), "--target", str(d / f"target-{tag}.obj"),
                                    "--guides", "20", "--out", str(tmp_path / f"{tag}.json"), "--quiet"])
        assert code == 0, err
        documents[tag] = json.loads((tmp_path / f"{tag}.json").read_text())
    upright, rotated = (np.array(documents[tag]["points"]) for tag in ("y-up", "z-up"))
    assert documents["z-up"]["units"] == "m" and len(rotated) > 20
    assert np.abs(rotated - frame.axes_out(upright)).max() < 1e-12
    # passed back as it is, in the file's frame: the hairline stays where it is
    out = tmp_path / "out"
    out.mkdir()
    code, _, err = run(capsys, ["retarget", "--source", str(d / "source-z-up.obj"), "--hair", str(d / "hair-z-up.data"),
                                "--target", str(d / "target-z-up.obj"), "--guides", "20", "--out",
                                str(out / "result.data"), "--report", str(out / "report.json"), "--max-iterations",
                                "4", "--workers", "1", "--quiet", "--hairline-curve", str(tmp_path / "z-up.json")])
    assert code == 0, err
    assert json.loads((out / "report.json").read_text())["metrics"]["hairline"]["max_travel_m"] < 1e-6


def test_a_groom_off_its_scalp_is_preprocessed_with_one_warning_line(capsys, mm_world, tmp_path):
    from hairport.solver.mesh.query import MeshQuery

    d = mm_world["dir"]
    source = load_character(d / "source.obj")
    hair = read_hair(d / "hair.npz")
    normals = MeshQuery(source.vertices, source.faces).signed_distance(hair.points[hair.roots]).normal
    write_hair(tmp_path / "lifted.npz", hair.with_points(hair.points + 0.004 * np.repeat(normals, hair.counts, axis=0)))
    code, stdout, err = run(capsys, ["preprocess", "--source", str(d / "source.obj"), "--hair",
                                     str(tmp_path / "lifted.npz"), "--out", str(tmp_path / "lifted.hpa"), "--quiet"])
    assert code == 0, err
    assert err.splitlines() == [f"hairport: warning: {hair.n_strands} of {hair.n_strands} roots sit more than 1 mm "
                                "off the source body (mean 4.00 mm, largest 4.00 mm); each is anchored at its "
                                "closest point on the body"]
    assert "50 strands" in stdout
    # the artifact keeps the input section: a retarget from it reports it
    code, _, err = run(capsys, ["retarget", "--adaptable", str(tmp_path / "lifted.hpa"), "--target",
                                str(d / "target.obj"), "--out", str(tmp_path / "out.npz"), "--report",
                                str(tmp_path / "report.json"), "--method", "root-translate", "--quiet"])
    assert code == 0 and err == "", err
    section = json.loads((tmp_path / "report.json").read_text())["metrics"]["input"]
    assert section["root_distance_m"]["off_surface"] == hair.n_strands and len(section["warnings"]) == 1
    assert abs(section["root_distance_m"]["mean"] - 0.004) < 1e-4
