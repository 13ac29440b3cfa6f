"""The frames of a target sequence: several mesh files with their own rigs, or an animated USD stage (time-sampled
points under an animated transform, in centimetres and Z up) read at its time codes; what is not a sequence is
refused with a code that names it."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom, Vt

from hairport.solver.io.character.frames import read_character_frames
from hairport.solver.io.character.obj import write_obj
from hairport.solver.model.errors import InputError
from hairport.solver.model.frame_range import FrameRange
from hairport.solver.synthetic import toy
from hairport.solver.synthetic.makehuman import write_character
from tests.solver.synthetic.toy_fixtures import PRESET_B

#: the stage's time codes: 1001, 1002, ... (a DCC's frame numbers)
FIRST_FRAME = 1001
SAMPLES = 4
#: the animated transform's motion along the stage's X per frame (cm)
DRIFT_CM = 2.0


@pytest.fixture(scope="module")
def bodies():
    source = toy.toy_character(name="source")
    other = toy.toy_character(**PRESET_B, name="other")
    return [source.vertices + t * (other.vertices - source.vertices) for t in np.linspace(0, 1, SAMPLES)], source


def animated_stage(path, frames, faces, *, samples=True) -> None:
    """A mesh whose points (canonical meters -> centimetres, Z up) are time-sampled from ``FIRST_FRAME`` on, under an
    Xform that drifts ``DRIFT_CM`` a frame along X."""
    stage = Usd.Stage.CreateNew(str(path))
    stage.SetTimeCodesPerSecond(30.0)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    xform = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(xform.GetPrim())
    translate = xform.AddTranslateOp()
    mesh = UsdGeom.Mesh.Define(stage, "/World/body")
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(faces), 3, dtype=np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(faces.astype(np.int32).ravel()))
    points = mesh.CreatePointsAttr()
    for number, vertices in enumerate(frames):
        z_up = vertices[:, [0, 2, 1]] * np.array([1.0, -1.0, 1.0]) * 100.0
        time = FIRST_FRAME + number if samples else Usd.TimeCode.Default()
        points.Set(Vt.Vec3fArray.FromNumpy(z_up.astype(np.float32)), time)
        translate.Set(Gf.Vec3d(DRIFT_CM * number, 0.0, 0.0), time)
    stage.Save()


def test_an_animated_stage_is_read_at_its_time_codes(tmp_path, bodies):
    frames, source = bodies
    animated_stage(tmp_path / "anim.usda", frames, source.faces)
    read = read_character_frames([tmp_path / "anim.usda"], FrameRange.parse("1001:1004"))
    characters = read.characters
    assert read.times == [1001.0, 1002.0, 1003.0, 1004.0] and read.units == "cm" and read.frames_per_second == 30.0
    for number, (character, vertices) in enumerate(zip(characters, frames)):
        assert character.skeleton is None and np.array_equal(character.faces, source.faces)
        z_up = vertices[:, [0, 2, 1]] * np.array([1.0, -1.0, 1.0])  # meters, the stage's axes
        assert np.abs(character.vertices - z_up - [0.01 * DRIFT_CM * number, 0.0, 0.0]).max() < 1e-6
    # between samples USD interpolates linearly; a step picks every other frame
    read = read_character_frames([tmp_path / "anim.usda"], FrameRange.parse("1001:1002:0.5"))
    halves = read.characters
    assert read.times == [1001.0, 1001.5, 1002.0]
    assert np.allclose(halves[1].vertices, 0.5 * (halves[0].vertices + halves[2].vertices), atol=1e-6)


@pytest.mark.parametrize("frames, code, word", [("1000:1003", "bad_frames", "1001"), ("1001:1009", "bad_frames", "1004")])
def test_frames_beyond_the_samples_are_refused(tmp_path, bodies, frames, code, word):
    vertices, source = bodies
    animated_stage(tmp_path / "anim.usdc", vertices, source.faces)
    with pytest.raises(InputError) as caught:
        read_character_frames([tmp_path / "anim.usdc"], FrameRange.parse(frames))
    assert caught.value.code == code and word in caught.value.problem


def test_a_still_stage_or_a_still_format_is_not_animated(tmp_path, bodies):
    vertices, source = bodies
    animated_stage(tmp_path / "still.usda", vertices[:1], source.faces, samples=False)
    write_obj(tmp_path / "body.obj", source.vertices, source.faces, "a still body")
    for name, word in (("still.usda", "time sample"), ("body.obj", "one body")):
        with pytest.raises(InputError) as caught:
            read_character_frames([tmp_path / name], FrameRange.parse("0:3"))
        assert caught.value.code == "not_animated" and word in caught.value.problem
    with pytest.raises(InputError) as caught:
        read_character_frames([tmp_path / "body.obj"])
    assert caught.value.code == "bad_frames"


def test_a_skeleton_animation_with_a_blend_shape_is_evaluated_at_each_time(tmp_path, bodies):
    """A skinned body posed by a UsdSkel.Animation (its points not time-sampled): the blend shape's weight and the
    root joint's translation at each time code, skinned by UsdSkel, in world space (through the Xform above the rig,
    which the stage's coordinates subtract)."""
    from tests.solver.io.character.usd_samples import Y_UP_TO_Z_UP, add_skel_animation, write_scene

    _, source = bodies
    other = toy.toy_character(**PRESET_B)
    write_scene(tmp_path / "skel.usda", source)
    add_skel_animation(tmp_path / "skel.usda", source, other, [1001.0, 1002.0, 1003.0], DRIFT_CM)
    read = read_character_frames([tmp_path / "skel.usda"], FrameRange.parse("1001:1003:0.5"))
    assert read.times == [1001.0, 1001.5, 1002.0, 1002.5, 1003.0] and read.units == "cm"
    for character, time in zip(read.characters, read.times, strict=True):
        weight = (time - 1001.0) / 2.0
        expected = (source.vertices + weight * (other.vertices - source.vertices)) @ Y_UP_TO_Z_UP
        expected[:, 0] += 0.01 * DRIFT_CM * (time - 1001.0)
        assert np.abs(character.vertices - expected).max() < 1e-5, time
        assert np.array_equal(character.faces, source.faces)
    with pytest.raises(InputError) as caught:
        read_character_frames([tmp_path / "skel.usda"], FrameRange.parse("1001:1004"))
    assert caught.value.code == "bad_frames"


def test_a_stage_of_time_samples_alone_is_read_as_one_body_at_its_first_sample(tmp_path, bodies):
    """An animated export authors no default points: a still read (an upload, a single retarget) takes frame 1001,
    through the transform at that time."""
    from hairport.solver.io.character.load import read_character

    frames, source = bodies
    animated_stage(tmp_path / "anim.usda", frames, source.faces)
    character, units = read_character(tmp_path / "anim.usda")
    first = read_character_frames([tmp_path / "anim.usda"], FrameRange.parse("1001:1001")).characters[0]
    assert units == "cm" and character.n_vertices == source.n_vertices
    assert np.abs(character.vertices - first.vertices).max() < 1e-9


def test_several_meshes_are_frames_with_their_own_rigs(tmp_path, bodies):
    vertices, source = bodies
    paths = []
    for number, frame in enumerate(vertices):
        body = toy.toy_character(**PRESET_B) if number == SAMPLES - 1 else None
        character = body or type(source)(frame, source.faces, source.skeleton, source.weights, name=f"f{number}")
        write_character(character, tmp_path / f"f{number}.obj", tmp_path / f"f{number}.skeleton.json")
        paths.append(tmp_path / f"f{number}.obj")
    read = read_character_frames(paths)
    characters = read.characters
    assert read.times == [0.0, 1.0, 2.0, 3.0] and read.units == "m" and read.frames_per_second == 24.0
    assert all(character.skeleton is not None for character in characters)
    assert np.allclose(characters[1].vertices, vertices[1], atol=1e-6)
    read = read_character_frames(paths, FrameRange.parse("1:3:2"))
    assert read.times == [1.0, 3.0] and np.allclose(read.characters[0].vertices, vertices[1], atol=1e-6)


@pytest.mark.parametrize("kind", ["meshes", "stage"])
def test_frames_above_the_sequences_vertex_bound_are_too_large(tmp_path, bodies, monkeypatch, kind):
    """Every frame's mesh is held at once: more vertices in all than MAX_SEQUENCE_VERTICES is refused, whether the
    frames are files or one stage's time samples."""
    from hairport.solver.io.character import frames as frames_module

    vertices, source = bodies
    monkeypatch.setattr(frames_module, "MAX_SEQUENCE_VERTICES", 2 * source.n_vertices)
    if kind == "meshes":
        for number in range(3):
            write_obj(tmp_path / f"f{number}.obj", vertices[number], source.faces, "a frame")
        paths, picked = [tmp_path / f"f{number}.obj" for number in range(3)], None
    else:
        animated_stage(tmp_path / "anim.usda", vertices, source.faces)
        paths, picked = [tmp_path / "anim.usda"], FrameRange.parse("1001:1003")
    assert len(read_character_frames(paths[:2] if picked is None else paths, picked if picked is None else
                                     FrameRange.parse("1001:1002")).characters) == 2  # at the bound: read
    with pytest.raises(InputError) as caught:
        read_character_frames(paths, picked)
    assert caught.value.code == "too_large" and f"{3 * source.n_vertices:,} vertices" in caught.value.problem


def test_meshes_stating_different_units_are_refused(tmp_path, bodies):
    vertices, source = bodies
    write_character(source, tmp_path / "a.obj", tmp_path / "a.skeleton.json")  # the sidecar says meters
    animated_stage(tmp_path / "b.usda", vertices[:1], source.faces, samples=False)  # the stage centimetres
    with pytest.raises(InputError) as caught:
        read_character_frames([tmp_path / "a.obj", tmp_path / "b.usda"])
    assert caught.value.code == "units_mismatch" and "cm" in caught.value.problem
