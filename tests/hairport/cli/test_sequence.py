"""``hairport retarget`` onto a sequence: several --target meshes or --frames of an animated USD stage, written as
one animated file or one file per frame, with per-frame previews and one report; plans that cannot be carried out
exit 2 before any work and leave nothing."""

from __future__ import annotations

import json

import numpy as np
import pytest
from pxr import Usd, UsdGeom

from hairport.solver.io.hair import read_hair
from hairport.solver.model.character import Character
from hairport.solver.synthetic import toy
from hairport.solver.synthetic.makehuman import write_character
from tests.hairport.cli.helpers import assert_input_error, assert_nothing_written, run
from tests.solver.io.character.gltf.test_morphs import morph_file
from tests.solver.io.character.test_alembic import animated_archive
from tests.solver.io.character.test_frames import animated_stage
from tests.solver.synthetic.toy_fixtures import PRESET_B

FRAMES = 3


@pytest.fixture(scope="module")
def sweep(world, tmp_path_factory):
    """The world's source body swept in ``FRAMES`` straight vertex steps to a larger toy, as OBJ files with their
    sidecars and as an animated USD stage (centimetres, Z up, time codes from 1001)."""
    d = tmp_path_factory.mktemp("sweep")
    source = world["source"]
    other = toy.toy_character(**PRESET_B)
    paths = []
    for number, t in enumerate(np.linspace(0.0, 1.0, FRAMES)):
        body = Character(source.vertices + t * (other.vertices - source.vertices), source.faces, source.skeleton,
                         source.weights, name=f"frame{number}")
        write_character(body, d / f"frame{number}.obj", d / f"frame{number}.skeleton.json")
        paths.append(str(d / f"frame{number}.obj"))
    vertices = [source.vertices + t * (other.vertices - source.vertices) for t in np.linspace(0.0, 1.0, FRAMES)]
    animated_stage(d / "anim.usda", vertices, source.faces)
    return {"dir": d, "meshes": paths, "stage": str(d / "anim.usda")}


def sequence_args(world, out, targets, *extra, name="hair.usda") -> list[str]:
    d = world["dir"]
    return ["retarget", "--source", str(d / "source.obj"), "--hair", str(d / "hair.data"), "--target", *targets,
            "--out", str(out / name), "--quiet", *extra]


def test_several_meshes_make_one_animated_file_a_report_and_a_preview_per_frame(capsys, world, sweep, out):
    code, printed, err = run(capsys, sequence_args(world, out, sweep["meshes"], "--report", str(out / "report.json"),
                                                   "--preview", str(out / "preview.##.png")))
    assert code == 0, err
    assert sorted(p.name for p in out.iterdir()) == ["hair.usda", "preview.00.png", "preview.01.png",
                                                     "preview.02.png", "report.json"]
    report = json.loads((out / "report.json").read_text())
    assert report["summary"]["frames"] == FRAMES and report["summary"]["penetrating_particles_max"] == 0
    assert [frame["time"] for frame in report["frames"]] == [0.0, 1.0, 2.0]
    # a sequence's frames take the spacing term unless --spacing names a weight (its energy is then reported)
    assert all(frame["metrics"]["energy_spacing_per_particle"] >= 0 for frame in report["frames"])
    assert f"{FRAMES} frames" in printed
    stage = Usd.Stage.Open(str(out / "hair.usda"))
    points = UsdGeom.BasisCurves(stage.GetPrimAtPath("/Groom/hair")).GetPointsAttr()
    assert points.GetTimeSamples() == [0.0, 1.0, 2.0]
    # frame 0 is the source's own body: the groom comes back where it was
    assert np.abs(np.array(points.Get(0.0)) - world["hair"].points).max() < 1e-4
    moved = np.linalg.norm(np.array(points.Get(2.0)) - np.array(points.Get(0.0)), axis=1)
    assert moved.max() > 5e-3


def test_one_file_per_frame_with_the_frame_number(capsys, world, sweep, out):
    code, _, err = run(capsys, sequence_args(world, out, sweep["meshes"], "--frames", "1:2", "--temporal", "1e4",
                                             "--spacing", "0", "--report", str(out / "report.json"),
                                             name="hair.####.npz"))
    assert code == 0, err
    assert sorted(p.name for p in out.iterdir()) == ["hair.0001.npz", "hair.0002.npz", "report.json"]
    report = json.loads((out / "report.json").read_text())
    assert not any("energy_spacing_per_particle" in frame["metrics"] for frame in report["frames"])  # --spacing 0
    first = read_hair(out / "hair.0001.npz")
    assert first.n_particles == world["hair"].n_particles and np.isfinite(first.points).all()


def test_an_animated_stage_is_retargeted_at_its_frames(capsys, world, sweep, out):
    code, _, err = run(capsys, sequence_args(world, out, [sweep["stage"]], "--frames", "1001:1003:2",
                                             "--report", str(out / "report.json"), name="hair.abc"))
    assert code == 0, err
    report = json.loads((out / "report.json").read_text())
    assert [frame["time"] for frame in report["frames"]] == [1001.0, 1003.0]
    assert report["summary"]["penetrating_particles_max"] == 0
    assert report["frames"][0]["metrics"]["input"]["target"]["units"] == "cm"
    from alembic3d import Abc, AbcGeom

    curves = Abc.IArchive(str(out / "hair.abc")).getTop().getChild("groom").getChild("hair")
    sampling = AbcGeom.ICurves(curves, Abc.WrapExistingFlag.kWrapExisting).getSchema().getTimeSampling()
    assert [sampling.getSampleTime(i) for i in range(2)] == pytest.approx([1001 / 30, 1003 / 30])  # the stage's rate


@pytest.mark.parametrize("extra, name, words", [
    ((), "hair.npz", ("animated", "####")),
    (("--preview", "preview.png"), "hair.usda", ("one per frame",)),
    (("--frames", "0:5"), "hair.usda", ("3 frames",)),
    (("--temporal", "-1"), "hair.usda", ("temporal",)),
    (("--no-warm-start", "--temporal", "10"), "hair.usda", ("warm",)),
    (("--target-skeleton", "x.json"), "hair.usda", ("sidecar",)),
    (("--landmarks", "marks.json"), "hair.usda", ("landmarks",)),
])
def test_a_plan_that_cannot_be_carried_out_exits_2_and_writes_nothing(capsys, world, sweep, out, extra, name, words):
    extra = [str(out / value) if value.endswith(".png") else value for value in extra]
    code, _, err = run(capsys, sequence_args(world, out, sweep["meshes"], *extra, name=name))
    assert_input_error(code, err, *words)
    assert_nothing_written(out)


def test_sequence_options_on_one_target_are_refused(capsys, world, out):
    args = sequence_args(world, out, [str(world["dir"] / "target.obj")], "--temporal", "1e4", name="hair.npz")
    assert_input_error(*run(capsys, args)[::2], "sequence")
    assert_nothing_written(out)


def test_frames_of_another_mesh_are_refused(capsys, world, sweep, out):
    code, _, err = run(capsys, sequence_args(world, out, [sweep["meshes"][0], str(world["dir"] / "bare.obj"),
                                                          str(sweep["dir"] / "anim.usda")]))
    assert_input_error(code, err)
    assert_nothing_written(out)


def test_a_gltf_body_is_swept_by_the_morph_weights_given(capsys, world, out, tmp_path):
    source, other = world["source"], toy.toy_character(**PRESET_B)
    morph_file(tmp_path / "body.glb", source, np.stack([other.vertices - source.vertices]), animated=False)
    (tmp_path / "weights.json").write_text("[[0.0], [0.5], [1.0]]")
    args = sequence_args(world, out, [str(tmp_path / "body.glb")], "--morph-weights", str(tmp_path / "weights.json"),
                         "--frames", "1:2", "--report", str(out / "report.json"), name="hair.####.npz")
    code, _, err = run(capsys, args)
    assert code == 0, err
    assert sorted(p.name for p in out.iterdir()) == ["hair.0001.npz", "hair.0002.npz", "report.json"]
    assert json.loads((out / "report.json").read_text())["summary"]["penetrating_particles_max"] == 0
    for path in out.iterdir():
        path.unlink()
    (tmp_path / "weights.json").write_text("[[0.0, 1.0], [0.5, 1.0], [1.0, 1.0]]")
    assert_input_error(*run(capsys, args)[::2], "morph targets")
    assert_nothing_written(out)


def test_an_alembic_animated_mesh_is_a_sequence(capsys, world, out, tmp_path):
    source, other = world["source"], toy.toy_character(**PRESET_B)
    animated_archive(tmp_path / "body.abc", source.faces, [source.vertices, 0.5 * (source.vertices + other.vertices)])
    code, _, err = run(capsys, sequence_args(world, out, [str(tmp_path / "body.abc")], "--frames", "0:1", "--units",
                                             "m", "--report", str(out / "report.json"), name="hair.usdc"))
    assert code == 0, err
    report = json.loads((out / "report.json").read_text())
    assert report["summary"]["frames"] == 2 and report["summary"]["penetrating_particles_max"] == 0
    assert report["frames"][1]["metrics"]["coherence"]["largest_jump_m"] > 1e-3
