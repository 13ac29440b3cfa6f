"""Pipeline formats end to end on the command line: a USD stage with a skinned body and a groom in
centimetres, Z-up, under a translated Xform; an Unreal-convention Alembic groom. Units, axis and transform
are honoured, attributes come back unchanged beside the new positions."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Usd, UsdGeom

from hairport.solver import pipeline
from hairport.solver.io.character import load_character
from hairport.solver.io.hair import read_hair_report
from hairport.solver.mesh.collision import collision_query
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import PRESETS, build_character
from hairport.solver.transfer.anchors import root_targets
from tests.hairport.cli.helpers import run
from tests.solver.io.character.usd_samples import Y_UP_TO_Z_UP, write_scene
from tests.solver.io.hair.abc_samples import UNIFORM, VERTEX, general_properties, write_groom

#: integration, not unit: USD and Alembic files through the command line: sandboxed child processes
pytestmark = pytest.mark.integration

METHOD = "root-translate+pushout"  # the files are under test here, not the solver
#: stage coordinates are float32 centimetres: ~1e-7 relative, a few micrometres on a body
STAGE_TOLERANCE_M = 2e-5


@pytest.fixture(scope="module")
def scene(tmp_path_factory) -> dict:
    folder = tmp_path_factory.mktemp("usd-scene")
    source = build_character(PRESETS["average-female"])
    target = build_character(PRESETS["heavy-male"])
    hair = generate_groom(source, "short", 80, 10, seed=4)
    write_scene(folder / "source.usda", source, hair, extra_mesh=True)
    write_scene(folder / "target.usdc", target)
    adaptable = pipeline.preprocess(source, hair)
    expected = pipeline.retarget(adaptable, target, pipeline.RetargetOptions(method=METHOD)).hair
    roots = root_targets(target, adaptable.anchors.face[hair.roots], adaptable.anchors.barycentric[hair.roots])
    return {"dir": folder, "source": source, "target": target, "hair": hair, "expected": expected, "roots": roots}


def canonical(points_cm: np.ndarray) -> np.ndarray:
    """Stage world coordinates (cm, Z-up) -> hairport's canonical meters, Y-up."""
    return points_cm * 0.01 @ Y_UP_TO_Z_UP.T


def test_a_usd_stage_in_centimetres_z_up_under_an_xform_retargets_in_its_own_frame(capsys, scene, tmp_path):
    d = scene["dir"]
    out = tmp_path / "result.usda"
    code, _, err = run(capsys, ["retarget", "--source", str(d / "source.usda"), "--hair", str(d / "source.usda"),
                                "--target", str(d / "target.usdc"), "--out", str(out), "--method", METHOD, "--quiet"])
    assert code == 0, err
    stage = Usd.Stage.Open(str(out))
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01) and UsdGeom.GetStageUpAxis(stage) == "Z"
    report = read_hair_report(out, units="cm")
    result = canonical(report.hair.points / 0.01)
    assert np.abs(result - scene["expected"].points).max() < STAGE_TOLERANCE_M
    roots = result[report.hair.roots]
    assert np.linalg.norm(roots - scene["roots"], axis=1).max() < STAGE_TOLERANCE_M
    target = scene["target"]
    inside = collision_query(target.vertices, target.faces).signed_distance(result).distance < -STAGE_TOLERANCE_M
    assert int(inside.sum()) == 0
    np.testing.assert_array_equal(report.hair.attributes["strand_id"].values, np.arange(scene["hair"].n_strands))


def test_the_usd_body_and_its_skeleton_load_in_the_stage_frame(scene):
    body = load_character(scene["dir"] / "source.usda")
    source = scene["source"]
    assert body.name == "source.usda" and len(body.vertices) == len(source.vertices)  # the skinned body, not the prop
    np.testing.assert_allclose(canonical(body.vertices / 0.01), source.vertices, atol=STAGE_TOLERANCE_M)
    np.testing.assert_array_equal(body.faces, source.faces)
    assert body.skeleton.names == source.skeleton.names
    np.testing.assert_allclose(canonical(body.skeleton.heads / 0.01), source.skeleton.heads, atol=STAGE_TOLERANCE_M)
    assert abs(body.weights - source.weights).max() < 1e-6


def test_an_unreal_alembic_groom_retargets_with_only_positions_changed(capsys, scene, tmp_path):
    d, hair = scene["dir"], scene["hair"]
    rng = np.random.default_rng(9)
    guides = (np.arange(hair.n_strands) % 10 == 0).astype(np.int16)
    groups = rng.integers(0, 3, hair.n_strands).astype(np.int32)
    colors = rng.random((hair.n_particles, 3)).astype(np.float32)
    widths = np.full(hair.n_particles, 0.008, dtype=np.float32)  # cm
    source_abc = tmp_path / "groom.abc"
    # in the body's frame: the stage's world, Z-up, in centimetres
    write_groom(source_abc, hair.points @ Y_UP_TO_Z_UP / 0.01, hair.counts, widths=widths, params=[
        ("groom_guide", "OInt16GeomParam", "ShortArray", guides, UNIFORM),
        ("groom_group_id", "OInt32GeomParam", "IntArray", groups, UNIFORM),
        ("groom_color", "OC3fGeomParam", "C3fArray", colors.tolist(), VERTEX),
        ("groom_width", "OFloatGeomParam", "FloatArray", widths, VERTEX),
    ])
    out = tmp_path / "result.abc"
    code, _, err = run(capsys, ["retarget", "--source", str(d / "source.usda"), "--hair", str(source_abc),
                                "--hair-units", "cm", "--target", str(d / "target.usdc"),
                                "--out", str(out), "--method", METHOD, "--quiet"])
    assert code == 0, err
    before, after = read_hair_report(source_abc, units="cm").hair, read_hair_report(out, units="cm").hair
    assert sorted(after.attributes) == sorted(before.attributes) == ["groom_group_id", "groom_guide"]
    for name, attribute in before.attributes.items():
        assert after.attributes[name].values.dtype == attribute.values.dtype
        np.testing.assert_array_equal(after.attributes[name].values, attribute.values)
    np.testing.assert_array_equal(after.offsets, before.offsets)
    np.testing.assert_array_equal(after.thickness, before.thickness)
    np.testing.assert_array_equal(after.color, before.color)
    assert np.linalg.norm(after.points - before.points, axis=1).mean() > 5e-3  # the groom did move
    properties = general_properties(out)
    assert properties["groom_version_major"] == ("kInt16POD", 1)
    assert properties["groom_version_minor"] == ("kInt16POD", 4)
    assert properties["groom_tool"][1].startswith("hairport ")


def test_convert_keeps_the_stage_frame_and_reads_one_prim(capsys, scene, tmp_path):
    d = scene["dir"]
    archive, stage_out = tmp_path / "groom.npz", tmp_path / "groom.usdc"
    code, _, err = run(capsys, ["convert", str(d / "source.usda"), str(archive), "--prim", "groom", "--quiet"])
    assert code == 0, err
    code, _, err = run(capsys, ["convert", str(archive), str(stage_out), "--quiet"])
    assert code == 0, err
    stage = Usd.Stage.Open(str(stage_out))
    assert UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01) and UsdGeom.GetStageUpAxis(stage) == "Z"
    before = read_hair_report(d / "source.usda", units="cm").hair
    after = read_hair_report(stage_out, units="cm").hair
    np.testing.assert_allclose(after.points, before.points, rtol=0, atol=1e-7)  # world positions, float32 cm
    np.testing.assert_array_equal(after.attributes["strand_id"].values, before.attributes["strand_id"].values)
    code, _, err = run(capsys, ["convert", str(d / "source.usda"), str(archive), "--prim", "fringe", "--quiet"])
    assert code == 2 and "no BasisCurves prim named 'fringe'" in err


def test_guides_flagged_in_the_groom_are_the_solver_guides_and_are_written_back(capsys, scene, tmp_path):
    d, hair = scene["dir"], scene["hair"]
    flags = (np.arange(hair.n_strands) % 4 == 0).astype(np.int16)
    groom = tmp_path / "groom.abc"
    write_groom(groom, hair.points @ Y_UP_TO_Z_UP / 0.01, hair.counts,
                params=[("groom_guide", "OInt16GeomParam", "ShortArray", flags, UNIFORM)])
    out, report = tmp_path / "result.abc", tmp_path / "report.json"
    base = ["retarget", "--source", str(d / "source.usda"), "--hair", str(groom), "--hair-units", "cm",
            "--target", str(d / "target.usdc"), "--out", str(out), "--quiet", "--max-iterations", "3"]
    code, _, err = run(capsys, [*base, "--guides-from", "groom_guide", "--flag-guides", "--report", str(report)])
    assert code == 0, err
    import json

    assert json.loads(report.read_text())["inputs"]["guides"] == int(flags.sum()) == 20
    np.testing.assert_array_equal(read_hair_report(out, units="cm").hair.attributes["groom_guide"].values, flags)
    code, _, err = run(capsys, [*base, "--guides-from", "sim_guide"])
    assert code == 2 and "no per-strand attribute 'sim_guide'" in err and "'groom_guide'" in err
