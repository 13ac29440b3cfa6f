"""Tests for solver/body/orientation.py: up and front axes of a body and its groom, in every axis-aligned frame."""

import numpy as np
import pytest

from hairport.solver.body.orientation import (
    FRONT_BY_CONVENTION,
    infer_axes,
    infer_front,
    mirror_asymmetry,
    relative_axes,
)
from hairport.solver.model.character import Character
from hairport.solver.model.frame import AXES, InputFrame
from hairport.solver.model.hair import Hair
from hairport.solver.synthetic.groom import generate_groom
from tests.solver.frames import character_in, hair_in, head_only

ALL_FRAMES = [InputFrame(up=up, front=front) for up in AXES for front in AXES if up[1] != front[1]]


@pytest.fixture(scope="module")
def toy_groom(toy_a, query_a):
    return generate_groom(toy_a, "short", 120, 10, seed=4, query=query_a)


def misread(character, hair, rigged):
    """The frames among all 24 whose axes are not recovered, and the smallest confidences."""
    wrong, confidences = [], []
    for frame in ALL_FRAMES:
        guess = infer_axes(character_in(frame, character, rigged), hair_in(frame, hair))
        confidences.append((guess.up_confidence, guess.front_confidence))
        if (guess.up, guess.front) != (frame.up, frame.front):
            wrong.append((frame.up, frame.front, guess.up, guess.front))
    return wrong, np.min(confidences, axis=0)


def test_toy_axes_are_recovered_in_all_24_frames_with_and_without_a_rig(toy_a, toy_groom):
    for rigged in (True, False):
        wrong, confidence = misread(toy_a, toy_groom, rigged)
        assert wrong == [], (rigged, wrong)
        assert confidence.min() > 0.9, confidence
    guess = infer_axes(toy_a, toy_groom)
    assert (guess.up_how, guess.warnings()) == ("the head bone", [])
    assert "mirror symmetry" in guess.front_how


def test_a_makehuman_head_cut_at_the_neck_without_a_rig_in_every_frame():
    """The roots alone lean 30-38 degrees back on a head alone; the hang of the hair and the neck
    cut keep the up estimate within 15 degrees of the axis."""
    from hairport.solver.synthetic.makehuman import PRESETS, build_character

    body = build_character(PRESETS["heavy-male"])
    head = head_only(body)
    height = np.ptp(head.vertices[:, 1])
    assert head.n_faces < body.n_faces / 3 and 0.15 < height < 0.3, (head.n_faces, height)
    for style in ("short", "long"):
        hair = generate_groom(body, style, 150, 8, seed=1)
        wrong, confidence = misread(head, hair, rigged=False)
        assert wrong == [], (style, wrong)
        assert confidence.min() > 0.95, (style, confidence)


def test_given_axes_are_kept_and_weak_front_cues_fall_back_to_the_convention(toy_a, toy_groom):
    guess = infer_axes(toy_a, toy_groom, up="+y", front="-z")
    assert (guess.up, guess.front, guess.up_how, guess.front_how) == ("+y", "-z", "given", "given")
    # roots straight above the head's centre and strands hanging straight down: no face side to see
    top = toy_a.vertices[np.argmax(toy_a.vertices[:, 1])]
    hair = Hair.from_strands([np.array([top, top - [0.0, 0.1, 0.0]])] * 3)
    body = Character(toy_a.vertices, toy_a.faces)
    assert infer_front(body, hair, "+y") == (FRONT_BY_CONVENTION["+y"], "convention", 0.0) == ("+z", "convention", 0.0)


def test_mirror_asymmetry_is_zero_for_a_symmetric_set_and_positive_across_the_face(toy_a):
    rng = np.random.default_rng(1)
    half = rng.normal(size=(300, 3))
    symmetric = np.concatenate([half, half * [-1.0, 1.0, 1.0]])
    assert mirror_asymmetry(symmetric, np.array([1.0, 0.0, 0.0])) == pytest.approx(0.0, abs=1e-12)
    head = toy_a.vertices[toy_a.vertices[:, 1] > 1.6]
    across_sides = mirror_asymmetry(head, np.array([1.0, 0.0, 0.0]))
    across_face = mirror_asymmetry(head, np.array([0.0, 0.0, 1.0]))
    assert across_sides < 1e-3 and across_face > 5 * across_sides


def test_a_target_is_fitted_to_the_source_through_its_shared_vertices(toy_a, toy_b):
    for frame in (InputFrame(up="z", front="-y"), InputFrame(up="-x", front="y"), InputFrame()):
        up, front, confidence = relative_axes(toy_a.vertices, character_in(frame, toy_b).vertices * 7.0)
        assert (up, front) == (frame.up, frame.front) and confidence > 0.99


def test_a_mirrored_character_keeps_its_up_and_front_in_every_frame(toy_a, toy_groom):
    """x -> -x with the faces turned over (still counter-clockwise from outside): a left-handed export.
    Its up and front are still up and front; hairport's frame keeps it mirrored (a rotation cannot undo
    a mirror, and nothing downstream needs it undone)."""
    mirror = np.array([-1.0, 1.0, 1.0])
    skeleton = toy_a.skeleton
    mirrored = Character(toy_a.vertices * mirror, toy_a.faces[:, ::-1],
                         type(skeleton)(skeleton.names, skeleton.parents, skeleton.heads * mirror,
                                        skeleton.tails * mirror), toy_a.weights, "mirrored")
    hair = toy_groom.with_points(toy_groom.points * mirror)
    for rigged in (True, False):
        wrong, confidence = misread(mirrored, hair, rigged)
        assert wrong == [] and confidence.min() > 0.9, (rigged, wrong, confidence)
