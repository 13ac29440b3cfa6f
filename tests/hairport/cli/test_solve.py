"""``hairport preprocess``, ``retarget`` and ``hairline``: bad inputs exit 2 with one line and leave nothing;
outputs, report, preview, units; the artifact gives the one-shot result; hairline edits (on MakeHuman
characters: the toy groom does not reach the ears); grooms sunk into closed bodies and busts come out
whole, and a body that traps hair is an error."""

from __future__ import annotations

import json
import shutil
import struct
from pathlib import Path

import numpy as np
import pytest

from hairport import cli, solver
from hairport.settings import get_settings
from hairport.solver import options, pipeline
from hairport.solver.io.character import load_character
from hairport.solver.io.character.obj import write_obj
from hairport.solver.io.hair import read_hair, write_hair
from hairport.solver.mesh.collision import collision_query
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.errors import InputError
from hairport.solver.model.frame import InputFrame
from hairport.solver.synthetic import toy
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import write_character
from hairport.solver.transfer.anchors import root_targets
from tests.hairport.cli.helpers import (
    BASELINE,
    N_PARTICLES,
    N_STRANDS,
    assert_input_error,
    assert_nothing_written,
    call_log,
    retarget_args,
    run,
)
from tests.solver.depth_cases import TOY_CHEST_Y_M, chest_cut, keep_faces, sunk, trap
from tests.solver.frames import character_in, faces_only, hair_in, head_faces
from tests.solver.synthetic.toy_fixtures import PRESET_B

# float32 coordinates (.data, .hair, .ply) near 1.7 m round to within ~6e-8 m
FLOAT32_TOLERANCE_M = 1e-6


@pytest.fixture(scope="module")
def expected(world) -> dict:
    """The baseline result computed through the pipeline API (what the CLI must write)."""
    d = world["dir"]
    source = load_character(d / "source.obj")
    target = load_character(d / "target.obj")
    hair = read_hair(d / "hair.data")
    adaptable = pipeline.preprocess(source, hair)
    result = pipeline.retarget(adaptable, target, pipeline.RetargetOptions(method=BASELINE))
    roots = root_targets(target, adaptable.anchors.face[hair.roots], adaptable.anchors.barycentric[hair.roots])
    return {"hair": hair, "result": result.hair, "root_targets": roots}


def test_truncated_data_file(capsys, world, out, tmp_path):
    data = (world["dir"] / "hair.data").read_bytes()
    assert len(data) == 4 + N_STRANDS * (4 + 12 * N_PARTICLES)
    bad = tmp_path / "cut.data"
    bad.write_bytes(data[: len(data) // 2])  # inside the coordinates of strand 29
    code, stdout, err = run(capsys, retarget_args(world, out, hair=bad))
    assert_input_error(code, err, str(bad), "strand 29", "past the end of the file")
    assert stdout == ""
    assert_nothing_written(out)


def test_truncated_hair_file_in_header(capsys, world, out, tmp_path):
    data = (world["dir"] / "hair.hair").read_bytes()
    assert data[:4] == b"HAIR"
    bad = tmp_path / "cut.hair"
    bad.write_bytes(data[:50])
    code, _, err = run(capsys, retarget_args(world, out, hair=bad))
    assert_input_error(code, err, str(bad), "HAIR header", "128 bytes", "has 50")
    assert_nothing_written(out)


def test_oversized_count_in_data_header(capsys, world, out, tmp_path):
    bad = tmp_path / "huge.data"
    bad.write_bytes(struct.pack("<i", 2**31 - 1) + bytes(16))
    assert bad.stat().st_size == 20
    code, _, err = run(capsys, retarget_args(world, out, hair=bad))
    assert_input_error(code, err, str(bad), "2,147,483,647 strands", "the file has 20")
    assert_nothing_written(out)


def test_oversized_counts_in_hair_header(capsys, world, out, tmp_path):
    header = bytearray((world["dir"] / "hair.hair").read_bytes()[:128])
    struct.pack_into("<II", header, 4, 2**32 - 1, 2**32 - 1)  # hair count, point count
    bad = tmp_path / "huge.hair"
    bad.write_bytes(bytes(header))
    code, _, err = run(capsys, retarget_args(world, out, hair=bad))
    assert_input_error(code, err, str(bad), "4,294,967,295 strands", "the file has 128")
    assert_nothing_written(out)


def test_strand_count_above_configured_limit(capsys, world, out, monkeypatch):
    monkeypatch.setenv("HAIRPORT_MAX_STRANDS", "10")
    get_settings.cache_clear()
    try:
        code, _, err = run(capsys, retarget_args(world, out))
    finally:
        monkeypatch.delenv("HAIRPORT_MAX_STRANDS")
        get_settings.cache_clear()
    assert_input_error(code, err, "hair.data", "60 strands", "limit of 10")
    assert_nothing_written(out)


def test_nan_coordinate_in_hair(capsys, world, out, tmp_path):
    data = bytearray((world["dir"] / "hair.data").read_bytes())
    strand, particle = 3, 5
    offset = 4 + strand * (4 + 12 * N_PARTICLES) + 4 + 12 * particle + 4  # its y
    struct.pack_into("<f", data, offset, float("nan"))
    bad = tmp_path / "nan.data"
    bad.write_bytes(bytes(data))
    code, _, err = run(capsys, retarget_args(world, out, hair=bad))
    index = strand * N_PARTICLES + particle
    assert_input_error(code, err, str(bad), "non-finite coordinate", f"point {index}", f"strand {strand}")
    assert_nothing_written(out)


def test_target_of_another_toy_resolution_with_the_wrap_off(capsys, world, out, tmp_path, monkeypatch):
    monkeypatch.setattr(toy, "TOY_RINGS", toy.TOY_RINGS // 2)
    coarse = toy.toy_character(name="coarse")
    monkeypatch.undo()
    write_character(coarse, tmp_path / "coarse.obj", tmp_path / "coarse.skeleton.json")
    code, _, err = run(capsys, retarget_args(world, out, target=tmp_path / "coarse.obj", extra=["--wrap", "off"]))
    assert_input_error(code, err, "coarse.obj", "topology differs", "3842 vertices",
                       f"the target has {coarse.n_vertices}", "--wrap off keeps to the source's topology",
                       "--wrap auto wraps the source body onto this target")
    assert_nothing_written(out)


def test_target_icosphere_with_sidecar_and_the_wrap_off(capsys, world, out, tmp_path):
    import trimesh

    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.1)
    mesh = tmp_path / "sphere.obj"
    with open(mesh, "w") as f:
        np.savetxt(f, sphere.vertices, fmt="v %.9g %.9g %.9g")
        np.savetxt(f, sphere.faces + 1, fmt="f %d %d %d")
    document = json.loads((world["dir"] / "source.skeleton.json").read_text())
    document["weights"] = {}  # the source's weights index vertices the sphere does not have
    (tmp_path / "sphere.skeleton.json").write_text(json.dumps(document))
    code, _, err = run(capsys, retarget_args(world, out, target=mesh, extra=["--wrap", "off"]))
    assert_input_error(code, err, "sphere.obj", "topology differs", f"the target has {len(sphere.vertices)}")
    assert_nothing_written(out)


def test_skeleton_with_unknown_parent(capsys, world, out, tmp_path):
    shutil.copy(world["dir"] / "source.obj", tmp_path / "crooked.obj")
    document = json.loads((world["dir"] / "source.skeleton.json").read_text())
    neck = next(bone for bone in document["bones"] if bone["name"] == "neck_01")
    neck["parent"] = "no_such_bone"
    sidecar = tmp_path / "crooked.skeleton.json"
    sidecar.write_text(json.dumps(document))
    code, _, err = run(capsys, retarget_args(world, out, source=tmp_path / "crooked.obj"))
    assert_input_error(code, err, str(sidecar), "unknown parent", "no_such_bone", "neck_01")
    assert_nothing_written(out)
    # the same file given explicitly for the target
    code, _, err = run(capsys, retarget_args(world, out, extra=["--target-skeleton", str(sidecar)]))
    assert_input_error(code, err, str(sidecar), "unknown parent", "no_such_bone")
    assert_nothing_written(out)


def test_unknown_output_format_refused_before_any_work(capsys, world, out, monkeypatch):
    loads = call_log(monkeypatch, solver, "read_character")
    args = retarget_args(world, out, quiet=False, all_outputs=False)
    args[args.index("--out") + 1] = str(out / "result.foo")
    code, _, err = run(capsys, args)
    assert code == 2, err
    assert loads == [], "characters were loaded before the output format was checked"
    assert_input_error(code, err, "result.foo", "'.foo'", "unknown hair file type")  # also: no progress line
    assert_nothing_written(out)


def test_unknown_hair_format_refused_before_any_work(capsys, world, out, tmp_path, monkeypatch):
    hair = tmp_path / "hair.xyz"
    shutil.copy(world["dir"] / "hair.data", hair)
    loads = call_log(monkeypatch, solver, "read_character")
    code, _, err = run(capsys, retarget_args(world, out, hair=hair, quiet=False))
    assert code == 2, err
    assert loads == [], "characters were loaded before the hair format was checked"
    assert_input_error(code, err, str(hair), "'.xyz'", "unknown hair file type")  # also: no progress line
    assert_nothing_written(out)


@pytest.mark.parametrize("which", ["--hair", "--source", "--target", "--source-skeleton"])
def test_missing_input_file(capsys, world, out, tmp_path, which):
    missing = tmp_path / ("nowhere.data" if which == "--hair" else
                          "nowhere.skeleton.json" if which == "--source-skeleton" else "nowhere.obj")
    args = retarget_args(world, out)
    if which == "--source-skeleton":
        args += [which, str(missing)]
    else:
        args[args.index(which) + 1] = str(missing)
    code, _, err = run(capsys, args)
    line = assert_input_error(code, err, str(missing))
    assert "not found" in line.lower() or "no such file" in line.lower(), line
    assert_nothing_written(out)


@pytest.mark.parametrize("method", ["warp-drive", "global+pushout", "root-translate+pullin", ""])
def test_bad_method_lists_valid_methods(capsys, world, out, monkeypatch, method):
    preprocessed = call_log(monkeypatch, solver, "preprocess")
    code, _, err = run(capsys, retarget_args(world, out, method=method))
    line = assert_input_error(code, err, f"unknown method {method!r}", "+pushout")
    for name in options.METHODS:
        assert name in line, f"{name!r} not listed in {line!r}"
    assert preprocessed == [], "the method was checked only after preprocessing"
    assert_nothing_written(out)


def test_progress_lines_precede_the_error_without_quiet(capsys, world, out, tmp_path):
    bad = tmp_path / "cut.hair"
    bad.write_bytes((world["dir"] / "hair.hair").read_bytes()[:50])
    code, _, err = run(capsys, retarget_args(world, out, hair=bad, quiet=False))
    assert code == 2
    lines = err.splitlines()
    assert lines[-1].startswith("hairport: error:") and str(bad) in lines[-1]
    assert all(line.startswith("[") for line in lines[:-1]), err
    assert_nothing_written(out)


def test_failure_while_writing_outputs_leaves_nothing(capsys, world, out, monkeypatch):
    """The hair and the report are already in temporary files when the preview fails."""
    from hairport.solver.render import preview

    def broken(path, panels):
        Path(path).write_bytes(b"half a PNG")
        raise InputError("cannot render", str(path), "render_failed")

    monkeypatch.setattr(preview, "render_preview", broken)
    code, stdout, err = run(capsys, retarget_args(world, out))
    assert_input_error(code, err, "preview", "cannot render")
    assert stdout == ""
    assert_nothing_written(out)


def test_unwritable_output_is_one_line_error(capsys, world, out):
    """--out inside a path that is a regular file: the run must end with one error line."""
    blocker = out / "blocker"
    blocker.write_text("a file, not a folder")
    args = retarget_args(world, out, all_outputs=False)
    args[args.index("--out") + 1] = str(blocker / "result.data")
    try:
        code, _, err = run(capsys, args)
    except Exception as error:  # noqa: BLE001 - what the user would see is a traceback
        pytest.fail(f"main() raised {error!r} instead of printing one 'hairport: error:' line")
    assert code != 0
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("hairport: error:") and "blocker" in lines[0], err
    assert sorted(p.name for p in out.iterdir()) == ["blocker"]


MAGIC = {"data": struct.pack("<i", N_STRANDS), "hair": b"HAIR", "ply": b"ply\n", "npz": b"PK\x03\x04"}


@pytest.mark.parametrize("fmt", ["data", "hair", "ply", "npz"])
def test_output_format_follows_extension(capsys, world, expected, out, fmt):
    args = retarget_args(world, out, all_outputs=False)
    target = out / f"result.{fmt}"
    args[args.index("--out") + 1] = str(target)
    code, stdout, err = run(capsys, args)
    assert code == 0, err
    assert err == ""  # --quiet
    assert "penetrating particles" in stdout and "max root error" in stdout
    assert sorted(p.name for p in out.iterdir()) == [target.name]  # no temporary left
    assert target.read_bytes()[:4] == MAGIC[fmt]

    result = read_hair(target)
    source_hair = expected["hair"]
    assert result.n_strands == source_hair.n_strands == N_STRANDS
    assert result.n_particles == source_hair.n_particles
    np.testing.assert_array_equal(result.offsets, source_hair.offsets)
    tolerance = 1e-9 if fmt == "npz" else FLOAT32_TOLERANCE_M  # npz keeps float64
    np.testing.assert_allclose(result.points, expected["result"].points, rtol=0, atol=tolerance)
    root_error = np.linalg.norm(result.points[result.roots] - expected["root_targets"], axis=1).max()
    assert root_error <= tolerance


def test_report_contents(capsys, world, out):
    code, _, err = run(capsys, retarget_args(world, out))
    assert code == 0, err
    assert sorted(p.name for p in out.iterdir()) == ["preview.png", "report.json", "result.data"]
    report = json.loads((out / "report.json").read_text())

    metrics = report["metrics"]
    for key in ("penetrating_particles", "mean_segment_angle_rad", "interstrand_error_m", "root_to_target_max"):
        assert key in metrics, key
    energies = [key for key in metrics if key.startswith("energy_")]
    assert "energy_total_per_particle" in energies and len(energies) >= 4
    assert metrics["method"] == BASELINE
    assert metrics["particles"] == N_STRANDS * N_PARTICLES
    assert metrics["root_to_target_max"] < 1e-9
    assert all(np.isfinite(metrics[key]) for key in energies)

    timings = report["timings_s"]
    for stage in ("preprocess", "prepare", "initial_transfer", "baseline", "metrics"):
        assert stage in timings, stage
        assert isinstance(timings[stage], float) and timings[stage] >= 0

    d = world["dir"]
    assert report["inputs"] == {
        "source": str(d / "source.obj"), "target": str(d / "target.obj"), "hair": str(d / "hair.data"),
        "strands": N_STRANDS, "particles": N_STRANDS * N_PARTICLES, "guides": N_STRANDS, "units": "m",
    }


def test_preview_is_a_png(capsys, world, out):
    from PIL import Image

    args = retarget_args(world, out, all_outputs=False) + ["--preview", str(out / "preview.png")]
    code, _, err = run(capsys, args)
    assert code == 0, err
    path = out / "preview.png"
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with Image.open(path) as image:
        assert image.format == "PNG"
        width, height = image.size
        image.verify()
    assert width > 100 and height > 100


def test_units_cm_gives_the_meter_result(capsys, world, out):
    """The same groom in cm, read with --units cm (meshes keep their sidecar's meters)."""
    d = world["dir"]
    args = retarget_args(world, out, hair=d / "hair.npz", all_outputs=False)
    args[args.index("--out") + 1] = str(out / "meters.npz")
    code, _, err = run(capsys, args)
    assert code == 0, err
    args = retarget_args(world, out, hair=d / "hair_cm.npz", extra=["--units", "cm"], all_outputs=False)
    args[args.index("--out") + 1] = str(out / "centimeters.npz")
    args += ["--report", str(out / "cm.json")]
    code, _, err = run(capsys, args)
    assert code == 0, err
    assert json.loads((out / "cm.json").read_text())["inputs"]["units"] == "cm"
    with pytest.raises(InputError, match="units"):
        read_hair(out / "centimeters.npz")  # the output is written in cm too, and says so
    in_meters = read_hair(out / "meters.npz")
    from_cm = read_hair(out / "centimeters.npz", units="cm")
    difference = np.abs(from_cm.points - in_meters.points).max()
    assert difference < 1e-6, f"--units cm result differs from the meter result by {difference:.3g} m"


def test_target_without_skeleton_gets_the_source_skeleton(capsys, world, out):
    d = world["dir"]
    assert not (d / "bare.skeleton.json").exists()
    args = retarget_args(world, out, target=d / "bare.obj")
    code, _, err = run(capsys, args)
    assert code == 0, err
    result = read_hair(out / "result.data")
    assert (result.n_strands, result.n_particles) == (N_STRANDS, N_STRANDS * N_PARTICLES)
    report = json.loads((out / "report.json").read_text())
    assert report["metrics"]["root_to_target_max"] < 1e-9
    assert report["inputs"]["target"] == str(d / "bare.obj")


def test_heads_without_a_rig_in_millimetres_and_z_up_retarget_by_their_surface(capsys, world, out):
    """No skeleton, no units, Z up: everything inferred, the hair anchored by the source's surface."""
    d, frame = world["dir"], InputFrame("mm", "z", "-y")
    keep = head_faces(world["source"], 0.10)
    for name, character in (("source", world["source"]), ("target", toy.toy_character(**PRESET_B))):
        head = character_in(frame, faces_only(character, keep, name))
        write_obj(d / f"{name}-head-mm.obj", head.vertices, head.faces, "a head in mm, Z up, no rig")
    write_hair(d / "hair-mm.data", hair_in(frame, world["hair"]))
    args = retarget_args(world, out, source=d / "source-head-mm.obj", target=d / "target-head-mm.obj",
                         hair=d / "hair-mm.data", method="multiscale")
    code, _, err = run(capsys, args + ["--workers", "1"])
    assert code == 0, err
    metrics = json.loads((out / "report.json").read_text())["metrics"]
    assert metrics["anchoring"] == "surface" and metrics["penetrating_particles"] == 0
    assert (metrics["input"]["units"]["hair"], metrics["input"]["axes"]["up"]) == ("mm", "+z")
    result = read_hair(out / "result.data")  # in the groom's millimetres, Z up
    target = load_character(d / "target-head-mm.obj")
    roots = MeshQuery(target.vertices, target.faces).signed_distance(result.points[result.is_root]).distance
    assert np.abs(roots).max() < 1e-3  # mm: float32 coordinates near 1,700 mm
    code, _, err = run(capsys, args + ["--anchoring", "bones"])
    assert_input_error(code, err, "anchoring by bones needs", "skeleton")
    # a hairline edit takes the head's frame from the mesh (no head bone)
    code, _, err = run(capsys, args + ["--workers", "1", "--hairline", "receding:0.5"])
    assert code == 0, err
    hairline = json.loads((out / "report.json").read_text())["metrics"]["hairline"]
    assert hairline["head_frame"] == "mesh" and hairline["roots_moved"] > 0
    assert 0.5e-3 < hairline["mean_travel_m"] < 1e-2


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
    assert_input_error(code, err, "guides", "in [1, 20000]")
    assert_nothing_written(out)


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


@pytest.fixture(scope="module")
def bust_world(tmp_path_factory) -> dict:
    """MakeHuman busts as game characters come (eyes and teeth as separate shells, open at the
    chest and at the eye sockets, three non-manifold edges), a groom 2-5 mm off the skin; and
    the same pair with a gap in the mesh at the crown."""
    from hairport.solver.synthetic.makehuman import build_preset
    from hairport.solver.synthetic.makehuman.bust import build_bust, keep_faces
    from tests.solver.hairline.real_meshes import lifted_groom

    d = tmp_path_factory.mktemp("cli-bust")
    busts = [build_bust(name, open_eyes=True, fins=3) for name in ("average-female", "heavy-male")]
    crown = int(np.argmax(busts[0].vertices[:, 1]))
    keep = ~(busts[0].faces == crown).any(axis=1)
    for tag, pair in (("", busts), ("holed-", [keep_faces(bust, keep) for bust in busts])):
        for name, bust in zip(("female", "male"), pair):
            write_character(bust, d / f"{tag}{name}.obj", d / f"{tag}{name}.skeleton.json")
    write_hair(d / "short.data", lifted_groom(build_preset("average-female"), 80, 6))
    for tag in ("", "holed-"):
        code = cli.main(["preprocess", "--source", str(d / f"{tag}female.obj"), "--hair", str(d / "short.data"),
                         "--guides", "20", "--out", str(d / f"{tag}short.hpa"), "--quiet"])
        assert code == 0
    return {"dir": d, "adaptable": d / "short.hpa", "target": d / "male.obj"}


def test_hairline_edits_on_busts_with_eyes_teeth_and_open_borders(capsys, bust_world, out, tmp_path):
    curve = tmp_path / "peak.json"
    code, stdout, err = run(capsys, ["hairline", "--adaptable", str(bust_world["adaptable"]), "--target",
                                     str(bust_world["target"]), "--preset", "widows-peak", "--out", str(curve),
                                     "--quiet"])
    assert code == 0, err
    assert len(json.loads(curve.read_text())["points"]) > 20
    code, stdout, err = run(capsys, hairline_args(bust_world, out, "--hairline", "widows-peak:0.6"))
    assert code == 0, err
    metrics = json.loads((out / "report.json").read_text())["metrics"]
    assert metrics["penetrating_particles"] == 0 and metrics["hairline"]["roots_moved"] > 0


def test_a_gap_in_the_scalp_is_a_one_line_error(capsys, bust_world, tmp_path):
    d = bust_world["dir"]
    code, _, err = run(capsys, ["hairline", "--adaptable", str(d / "holed-short.hpa"), "--target",
                                str(d / "holed-male.obj"), "--out", str(tmp_path / "curve.json"), "--quiet"])
    assert_input_error(code, err, "the scalp under the roots has a hole", "gap in the mesh")
    assert not (tmp_path / "curve.json").exists()


@pytest.fixture(scope="module")
def sunk_world(world, tmp_path_factory) -> dict:
    """Two toys as closed bodies and as busts cut across the chest, a long groom sunk 3 and 6 cm
    into the source, and a body that traps hair with the hair it traps, as files. (Not the
    world's target: with the default neck radius its rings collapse at the crown, a toy with no
    chest to cut.)"""
    d = tmp_path_factory.mktemp("cli-depth")
    source, target = world["source"], toy.toy_character(**PRESET_B, name="target")
    keep = chest_cut(source, TOY_CHEST_Y_M)
    bodies = {"closed": (source, target),
              "bust": (keep_faces(source, keep), keep_faces(target, keep))}
    for name, (s, t) in bodies.items():
        write_character(s, d / f"{name}-source.obj", d / f"{name}-source.skeleton.json")
        write_character(t, d / f"{name}-target.obj", d / f"{name}-target.skeleton.json")
    groom = generate_groom(source, "long", 100, 16, seed=0)
    for depth in (3, 6):
        write_hair(d / f"sunk{depth}.npz", sunk(groom, depth / 100))
    body, hair = trap(source)
    write_character(body, d / "trap.obj", d / "trap.skeleton.json")
    write_hair(d / "trapped.npz", hair)
    return {"dir": d}


@pytest.mark.parametrize("depth", [3, 6])
@pytest.mark.parametrize("body", ["closed", "bust"])
def test_a_groom_sunk_into_its_body_retargets_with_no_particle_inside(capsys, sunk_world, out, body, depth):
    d = sunk_world["dir"]
    args = ["retarget", "--source", str(d / f"{body}-source.obj"), "--target", str(d / f"{body}-target.obj"),
            "--hair", str(d / f"sunk{depth}.npz"), "--out", str(out / "result.npz"), "--report",
            str(out / "report.json"), "--method", "multiscale", "--units", "m", "--quiet"]
    code, stdout, err = run(capsys, args)
    assert code == 0, err
    # the input report says the groom is inside its own body; nothing else is wrong
    assert all(line.startswith("hairport: warning:") for line in err.splitlines()), err
    assert "inside the source body" in err
    assert "penetrating particles 0," in stdout
    result = read_hair(out / "result.npz")
    target = load_character(d / f"{body}-target.obj")  # the file's numbers (the OBJ rounds to ~1e-9 m)
    distance = collision_query(target.vertices, target.faces).signed_distance(result.points).distance
    assert (distance[~result.is_root] < 0).sum() == 0
    assert np.abs(distance[result.is_root]).max() <= 1e-12
    metrics = json.loads((out / "report.json").read_text())["metrics"]
    assert metrics["input"]["source_penetration"]["particles"] > 100
    assert metrics["input"]["source_penetration"]["deepest_m"] > 0.02
    assert metrics["penetration_resolved"] == {"particles": 0, "deepest_m": 0.0}
    assert metrics["root_to_target_max"] <= 1e-12


@pytest.mark.parametrize("method", ["multiscale", "root-translate+pushout"])
def test_a_body_that_traps_hair_exits_2_with_one_line_and_writes_nothing(capsys, sunk_world, out, method):
    d = sunk_world["dir"]
    args = ["retarget", "--source", str(d / "trap.obj"), "--target", str(d / "trap.obj"), "--hair",
            str(d / "trapped.npz"), "--out", str(out / "result.npz"), "--report", str(out / "report.json"),
            "--preview", str(out / "preview.png"), "--method", method, "--units", "m", "--quiet"]
    code, _, err = run(capsys, args)
    line = [line for line in err.splitlines() if not line.startswith("hairport: warning:")]
    assert_input_error(code, "\n".join(line), "hair particles", "still inside after pushing them out",
                       "no penetration-free result")
    assert_nothing_written(out)


def wrap_args(world, out: Path, target: str, *extra: str) -> list[str]:
    return ["retarget", "--adaptable", str(world["adaptable"]), "--target", str(world["dir"] / target),
            "--out", str(out / "result.npz"), "--report", str(out / "report.json"), "--max-iterations", "8",
            "--workers", "1", "--quiet", *extra]


def test_a_remeshed_body_is_wrapped_and_the_hair_sits_on_it(capsys, remeshed_world, out):
    code, stdout, err = run(capsys, wrap_args(remeshed_world, out, "male.obj", "--preview", str(out / "p.png")))
    assert code == 0, err
    assert "wrapped the source body onto the target: residual mean" in stdout
    metrics = json.loads((out / "report.json").read_text())["metrics"]
    assert metrics["penetrating_particles"] == 0 and metrics["root_to_surface_max"] < 1e-6
    wrap = metrics["wrap"]
    assert wrap["residual_m"]["mean"] < 1e-3 and wrap["coverage"] > 0.95 and 0 < wrap["seconds"] < 30
    target = metrics["input"]["target"]
    assert (target["topology"], target["units"], target["up"], target["front"]) == ("other", "m", "+y", "+z")
    assert target["units_how"] == target["axes_how"] == "fitted to the source's head (another topology)"
    male = remeshed_world["male"]
    result = read_hair(out / "result.npz")
    roots = MeshQuery(male.vertices, male.faces).signed_distance(result.points[result.is_root]).distance
    assert np.abs(roots).max() < 1e-6
    # a target of the source's topology (here the source itself) is wrapped only when asked
    for mode, wrapped in (("auto", False), ("always", True)):
        code, _, err = run(capsys, wrap_args(remeshed_world, out, "female.obj", "--wrap", mode))
        assert code == 0, err
        metrics = json.loads((out / "report.json").read_text())["metrics"]
        assert ("wrap" in metrics) == wrapped and metrics["input"]["target"]["topology"] == "same"
    assert metrics["wrap"]["residual_m"]["mean"] < 1e-3


def test_a_head_cut_at_the_neck_in_millimetres_with_z_up_is_found_and_wrapped(capsys, remeshed_world, out):
    code, stdout, err = run(capsys, wrap_args(remeshed_world, out, "head.obj"))
    assert code == 0, err
    report = json.loads((out / "report.json").read_text())
    metrics, target = report["metrics"], report["metrics"]["input"]["target"]
    assert metrics["penetrating_particles"] == 0 and metrics["root_to_surface_max"] < 1e-6
    assert metrics["wrap"]["residual_m"]["mean"] < 1e-3 and report["timings_s"]["wrap"] > 0
    assert (target["units"], target["up"], target["front"]) == ("mm", "+z", "-y")
    assert target["head_fit_mm"] < 10 and target["size_ratio_to_source"] < 0.3
    # the result is in the groom's frame (meters, Y up): its roots on the head, read in the head file's frame
    head = remeshed_world["head"]
    result = read_hair(out / "result.npz")
    roots = MeshQuery(head.vertices, head.faces).signed_distance(result.points[result.is_root]).distance
    assert np.abs(roots).max() < 1e-6
    # stated in meters, the head is a hundredth of a head: refused, naming the units it is in
    code, _, err = run(capsys, wrap_args(remeshed_world, out, "head.obj", "--units", "m"))
    assert_input_error(code, err, "head.obj", "not a head's size in its units m", "give its units as mm")


def test_a_head_exported_by_trimesh_as_ply_in_millimetres_with_z_up_is_wrapped(capsys, remeshed_world, out, tmp_path):
    import trimesh

    head, frame = remeshed_world["head"], remeshed_world["head_frame"]
    in_file = frame.axes_out(head.vertices) / frame.scale  # millimetres, Z up, the face toward -Y
    trimesh.Trimesh(in_file, head.faces, process=False).export(tmp_path / "head.ply")
    args = wrap_args(remeshed_world, out, "male.obj")
    args[args.index("--target") + 1] = str(tmp_path / "head.ply")
    code, stdout, err = run(capsys, args)
    assert code == 0, err
    metrics = json.loads((out / "report.json").read_text())["metrics"]
    assert metrics["penetrating_particles"] == 0 and metrics["root_to_surface_max"] < 1e-6
    assert metrics["wrap"]["residual_m"]["mean"] < 1e-3 and "wrapped the source body" in stdout
    target = metrics["input"]["target"]
    assert (target["topology"], target["units"], target["up"], target["front"]) == ("other", "mm", "+z", "-y")


def head_landmarks(head_frame: InputFrame, target_vertices_in_meters=None) -> dict:
    """Crown, nape and the widest points of the average female's head (meters, Y up: the source file's frame)
    and of the heavy male's at the same vertices, in the head file's frame (millimetres, Z up, the face toward
    -Y), or in meters when ``target_vertices_in_meters`` is the heavy male's body itself."""
    from hairport.solver.body.head_frame import head_frame as frame_of
    from hairport.solver.synthetic.makehuman import PRESETS, build_character

    female, male = build_character(PRESETS["average-female"]), build_character(PRESETS["heavy-male"])
    frame = frame_of(female)
    head = np.flatnonzero(frame.head_vertices)
    up, front, side = frame.local(female.vertices[head]).T
    ids = {"crown": head[np.argmax(up)], "nape": head[np.argmin(front)], "left_ear_top": head[np.argmax(side)],
           "right_ear_top": head[np.argmin(side)]}
    target = male.vertices if target_vertices_in_meters is not None else head_frame.axes_out(male.vertices) / head_frame.scale
    return {"source": {name: female.vertices[i].tolist() for name, i in ids.items()},
            "target": {name: target[i].tolist() for name, i in ids.items()}}


def test_landmarks_in_each_files_frame_help_the_wrap_and_bad_ones_are_refused(capsys, remeshed_world, out, tmp_path):
    marks = tmp_path / "marks.json"
    marks.write_text(json.dumps(head_landmarks(remeshed_world["head_frame"])))
    code, _, err = run(capsys, wrap_args(remeshed_world, out, "head.obj", "--landmarks", str(marks)))
    assert code == 0, err
    wrap = json.loads((out / "report.json").read_text())["metrics"]["wrap"]
    # each landmark held to its target
    assert set(wrap["landmark_errors_m"]) == {"crown", "nape", "left_ear_top", "right_ear_top"}
    assert max(wrap["landmark_errors_m"].values()) < 5e-4 and wrap["landmarks_unused"] == []
    for written in out.iterdir():
        written.unlink()
    # the target's points given in meters, not in the head file's millimetres and axes
    marks.write_text(json.dumps(head_landmarks(remeshed_world["head_frame"], target_vertices_in_meters=True)))
    code, _, err = run(capsys, wrap_args(remeshed_world, out, "head.obj", "--landmarks", str(marks)))
    assert_input_error(code, err, "landmarks", "from the target body", "in its own file's coordinates")
    # a target of the source's topology is not wrapped: landmarks would change nothing
    code, _, err = run(capsys, wrap_args(remeshed_world, out, "female.obj", "--landmarks", str(marks)))
    assert_input_error(code, err, "landmarks", "is not wrapped", "wrap always")
    marks.write_text('{"source": {"crown": [0, 1.7, 0]}}')
    code, _, err = run(capsys, wrap_args(remeshed_world, out, "head.obj", "--landmarks", str(marks)))
    assert_input_error(code, err, "marks.json", '"source" and "target"')
    assert_nothing_written(out)


def test_another_topology_with_the_wrap_off_is_a_topology_mismatch(capsys, remeshed_world, out):
    code, _, err = run(capsys, wrap_args(remeshed_world, out, "male.obj", "--wrap", "off"))
    assert_input_error(code, err, "male.obj", "topology differs", "the target has 5000",
                       "--wrap off keeps to the source's topology")
    code, _, err = run(capsys, wrap_args(remeshed_world, out, "male.obj", "--wrap", "sometimes"))
    assert_input_error(code, err, "--wrap", "sometimes")
    assert_nothing_written(out)


def test_a_sphere_cannot_be_wrapped(capsys, remeshed_world, out):
    code, _, err = run(capsys, wrap_args(remeshed_world, out, "sphere.obj"))
    assert_input_error(code, err, "sphere.obj", "could not be wrapped", "residual", "--up-axis")
    assert_nothing_written(out)


def test_the_hairline_of_another_topology_is_read_on_the_wrapped_body(capsys, remeshed_world, out, tmp_path):
    curve = tmp_path / "current.json"
    base = ["hairline", "--adaptable", str(remeshed_world["adaptable"]), "--target",
            str(remeshed_world["dir"] / "male.obj"), "--out", str(curve), "--quiet"]
    code, _, err = run(capsys, base)
    assert code == 0, err
    document = json.loads(curve.read_text())
    male = remeshed_world["male"]
    distance = MeshQuery(male.vertices, male.faces).signed_distance(np.array(document["points"])).distance
    assert len(document["points"]) > 20 and np.abs(distance).max() < 5e-3  # the wrap's residual, on the scalp
    code, _, err = run(capsys, wrap_args(remeshed_world, out, "male.obj", "--hairline-curve", str(curve)))
    assert code == 0, err
    assert json.loads((out / "report.json").read_text())["metrics"]["hairline"]["max_travel_m"] < 1e-6
    code, _, err = run(capsys, [*base, "--wrap", "off"])
    assert_input_error(code, err, "topology differs", "--wrap off")
