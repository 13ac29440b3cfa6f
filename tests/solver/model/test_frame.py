"""Tests for solver/model/frame.py: axis names, the input frame's exact rotation, characters and hair moved into it."""

import numpy as np
import pytest

from hairport.solver.model.character import Character, Skeleton
from hairport.solver.model.errors import InputError
from hairport.solver.model.frame import (
    AXES,
    InputFrame,
    axis_name,
    character_axes_in,
    hair_axes_in,
    hair_axes_out,
    parse_axis,
)
from hairport.solver.model.hair import Hair

ALL_FRAMES = [InputFrame(up=up, front=front) for up in AXES for front in AXES if up[1] != front[1]]


def test_axis_names_parse_and_snap():
    assert [parse_axis(name) for name in ("x", "Y", "+z", "-X", " -y ")] == ["+x", "+y", "+z", "-x", "-y"]
    with pytest.raises(InputError) as error:
        parse_axis("up")
    assert error.value.code == "bad_axis" and "+x" in str(error.value)
    assert axis_name(np.array([0.1, -0.9, 0.3])) == "-y" and axis_name(np.array([0.0, 0.2, 0.21])) == "+z"


def test_every_frame_is_a_proper_rotation_that_maps_up_and_front_to_y_and_z():
    assert len(ALL_FRAMES) == 24
    for frame in ALL_FRAMES:
        rotation = frame.rotation
        assert np.array_equal(rotation @ rotation.T, np.eye(3)) and np.linalg.det(rotation) == pytest.approx(1.0)
        up = {"+": 1.0, "-": -1.0}[frame.up[0]] * np.eye(3)["xyz".index(frame.up[1])]
        front = {"+": 1.0, "-": -1.0}[frame.front[0]] * np.eye(3)["xyz".index(frame.front[1])]
        assert np.array_equal(rotation @ up, [0.0, 1.0, 0.0]) and np.array_equal(rotation @ front, [0.0, 0.0, 1.0])
    assert InputFrame().is_canonical_axes and np.array_equal(InputFrame().rotation, np.eye(3))
    # Blender's convention: Z up, the face toward -Y, the character's left still +X
    assert np.array_equal(InputFrame(up="z", front="-y").rotation[0], [1.0, 0.0, 0.0])


def test_axes_in_and_out_are_exact_inverses_and_match_the_matrix():
    rng = np.random.default_rng(0)
    points = rng.normal(size=(50, 3)) * 1.7
    for frame in ALL_FRAMES:
        moved = frame.axes_in(points)
        assert np.array_equal(moved, points @ frame.rotation.T)
        assert np.array_equal(frame.axes_out(moved), points)  # bit for bit: a signed permutation


def test_frame_checks_units_and_perpendicular_axes_and_round_trips_as_a_record():
    with pytest.raises(InputError) as error:
        InputFrame(up="z", front="-z")
    assert error.value.code == "bad_axis" and "perpendicular" in str(error.value)
    with pytest.raises(InputError) as error:
        InputFrame(units="ft")
    assert error.value.code == "unknown_units"
    frame = InputFrame("mm", "z", "-y")
    assert (frame.up, frame.front, frame.scale) == ("+z", "-y", 0.001)
    assert InputFrame.from_dict(frame.to_dict()) == frame and InputFrame.from_dict(None) == InputFrame()
    assert frame.describe() == "mm, up +z, front -y"


def test_characters_and_hair_move_into_the_frame_with_their_bones_and_thickness():
    vertices = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    skeleton = Skeleton(("head",), [-1], [[0.0, 0.0, 0.0]], [[0.0, 0.0, 2.0]])
    character = Character(vertices, faces, skeleton, np.ones((4, 1)), "tet")
    frame = InputFrame(up="z", front="-y")
    moved = character_axes_in(frame, character, 0.5)
    assert np.array_equal(moved.faces, faces) and moved.name == "tet"
    assert np.array_equal(moved.skeleton.tails, [[0.0, 1.0, 0.0]])  # the bone along input +Z now points up
    assert np.array_equal(moved.vertices, frame.axes_in(vertices) * 0.5)
    assert character_axes_in(InputFrame(), character) is character
    hair = Hair(np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 1.0]]), np.array([0, 2]), thickness=np.array([2.0, 2.0]))
    inside = hair_axes_in(frame, hair, 0.5)
    assert np.array_equal(inside.points, [[0.0, 0.5, 0.0], [0.0, 0.5, 0.5]])
    assert np.array_equal(inside.thickness, [1.0, 1.0]) and np.array_equal(inside.offsets, hair.offsets)
    assert np.array_equal(hair_axes_out(frame, hair_axes_in(frame, hair)).points, hair.points)
    assert hair_axes_out(InputFrame("mm"), hair) is hair  # units are the writer's business
