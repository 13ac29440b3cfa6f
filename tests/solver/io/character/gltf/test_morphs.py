"""A glTF mesh's morph targets as frames: weights from the file's animation (LINEAR, STEP, CUBICSPLINE) or given per
frame, offsets placed by the node's transform; meshes without targets or animation, and frames past the animation,
refused."""

from __future__ import annotations

import numpy as np
import pytest

from hairport.solver.io.character.frames import read_character_frames
from hairport.solver.io.character.gltf.morphs import read_morph_frames, sample_weights
from hairport.solver.model.errors import InputError
from hairport.solver.model.frame_range import FrameRange
from hairport.solver.synthetic import toy
from tests.solver.io.character.samples import GltfBuilder
from tests.solver.synthetic.toy_fixtures import PRESET_B

LIMITS = {"max_vertices": 10**6, "max_faces": 10**6}
#: the animation's keys (s) and each key's weights of the two targets
KEYS = np.array([0.0, 0.5, 1.0])
KEY_WEIGHTS = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 1.0]])


@pytest.fixture(scope="module")
def bodies():
    """The toy body and two morph targets: toward the other toy body, and a 1 cm lift."""
    base = toy.toy_character()
    grown = toy.toy_character(**PRESET_B).vertices - base.vertices
    lift = np.tile([0.0, 0.01, 0.0], (base.n_vertices, 1))
    return base, np.stack([grown, lift])


def morph_file(path, base, offsets, *, interpolation="LINEAR", animated=True, translation=(0.0, 0.0, 0.0)) -> None:
    builder = GltfBuilder()
    mesh = builder.mesh(base.vertices, base.faces, "body")
    primitive = builder.doc["meshes"][mesh]["primitives"][0]
    primitive["targets"] = [{"POSITION": builder.accessor(offset.astype("<f4"), "VEC3", 5126)} for offset in offsets]
    node = builder.node(mesh=mesh, name="body", translation=list(translation))
    builder.doc["scenes"][0]["nodes"].append(node)
    if animated:
        values = KEY_WEIGHTS
        if interpolation == "CUBICSPLINE":  # zero tangents: a smooth step between keys
            values = np.stack([np.zeros_like(KEY_WEIGHTS), KEY_WEIGHTS, np.zeros_like(KEY_WEIGHTS)], axis=1)
        sampler = {"input": builder.accessor(KEYS.astype("<f4"), "SCALAR", 5126),
                   "output": builder.accessor(values.reshape(-1).astype("<f4"), "SCALAR", 5126),
                   "interpolation": interpolation}
        builder.doc["animations"] = [{"samplers": [sampler],
                                      "channels": [{"sampler": 0, "target": {"node": node, "path": "weights"}}]}]
    path.write_bytes(builder.glb())


def test_the_animation_gives_each_frame_its_weights(tmp_path, bodies):
    base, offsets = bodies
    morph_file(tmp_path / "body.glb", base, offsets, translation=(0.0, 0.0, 0.2))
    read = read_character_frames([tmp_path / "body.glb"], FrameRange.parse("0:24:6"))  # 0, 0.25, 0.5, 0.75, 1 s
    assert read.times == [0.0, 6.0, 12.0, 18.0, 24.0] and read.units == "m"
    expected = [[0, 0], [0.5, 0], [1, 0], [0.75, 0.5], [0.5, 1]]
    for character, weights in zip(read.characters, expected):
        want = base.vertices + np.tensordot(weights, offsets, axes=1) + [0.0, 0.0, 0.2]
        assert np.abs(character.vertices - want).max() < 1e-6 and character.skeleton is None


@pytest.mark.parametrize("interpolation, at_quarter", [("STEP", [0.0, 0.0]), ("CUBICSPLINE", [0.5, 0.0])])
def test_step_and_cubic_animations(tmp_path, bodies, interpolation, at_quarter):
    base, offsets = bodies
    morph_file(tmp_path / "body.glb", base, offsets, interpolation=interpolation)
    frames = read_morph_frames(tmp_path / "body.glb", times_s=np.array([0.25, 0.5]), **LIMITS)
    want = base.vertices + np.tensordot(at_quarter, offsets, axes=1)
    assert np.abs(frames[0].vertices - want).max() < 1e-6
    assert np.abs(frames[1].vertices - (base.vertices + offsets[0])).max() < 1e-6


def test_weights_given_per_frame_replace_the_animation(tmp_path, bodies):
    base, offsets = bodies
    morph_file(tmp_path / "body.glb", base, offsets, animated=False)
    weights = np.array([[0.0, 0.0], [0.2, 0.0], [0.4, 1.0]])
    read = read_character_frames([tmp_path / "body.glb"], FrameRange.parse("1:2"), morph_weights=weights)
    assert read.times == [1.0, 2.0]
    assert np.abs(read.characters[1].vertices - (base.vertices + 0.4 * offsets[0] + offsets[1])).max() < 1e-6
    with pytest.raises(InputError) as caught:
        read_character_frames([tmp_path / "body.glb"], morph_weights=np.ones((2, 3)))
    assert caught.value.code == "bad_frames" and "2 morph targets" in caught.value.problem
    with pytest.raises(InputError) as caught:
        read_character_frames([tmp_path / "body.glb"], morph_weights=np.array([[np.nan, 0.0]]))
    assert caught.value.code == "bad_frames"


def test_what_is_not_a_morph_animation_is_refused(tmp_path, bodies):
    base, offsets = bodies
    morph_file(tmp_path / "still.glb", base, offsets, animated=False)
    morph_file(tmp_path / "plain.glb", base, offsets[:0], animated=False)
    morph_file(tmp_path / "body.glb", base, offsets)
    for name, frames, code, word in (("still.glb", "0:3", "not_animated", "weights"),
                                     ("plain.glb", "0:3", "not_animated", "no morph targets"),
                                     ("body.glb", "0:30", "bad_frames", "1.25")):
        with pytest.raises(InputError) as caught:
            read_character_frames([tmp_path / name], FrameRange.parse(frames))
        assert caught.value.code == code and word in caught.value.problem, caught.value.problem


def test_linear_weights_between_keys():
    weights = sample_weights(KEYS, KEY_WEIGHTS, "LINEAR", np.array([0.0, 0.25, 0.75, 1.0]))
    assert np.allclose(weights, [[0, 0], [0.5, 0], [0.75, 0.5], [0.5, 1]])
