"""The units and axes of a target of another topology, fitted to the source's head (solver/body/target_frame.py)."""

import numpy as np
import pytest

from hairport.solver.body.target_frame import fit_target_frame, frame_candidates
from hairport.solver.model.character import Character
from hairport.solver.model.frame import InputFrame
from hairport.solver.model.units import METERS_PER_UNIT
from hairport.solver.synthetic.makehuman import PRESETS, build_character
from hairport.solver.synthetic.remesh import head_cut, neck_height, remeshed_character


@pytest.fixture(scope="module")
def source():
    return build_character(PRESETS["average-female"])


@pytest.fixture(scope="module")
def heavy_male_remeshed():
    """The heavy male with another topology (5k vertices) and his head cut at the neck (canonical, meters)."""
    male = build_character(PRESETS["heavy-male"])
    body = remeshed_character(male, 5000, seed=2)
    return body, head_cut(body, neck_height(male))[0]


def written_in(character: Character, frame: InputFrame) -> Character:
    """The character as a file in ``frame``'s units and axes would hold it."""
    return Character(frame.axes_out(character.vertices) / METERS_PER_UNIT[frame.units], character.faces,
                     name=character.name)


def test_the_candidates_are_the_proper_axis_pairs_times_the_units():
    frames = frame_candidates(None, None, None)
    assert len(frames) == 6 * 4 * 4 and len(set(frames)) == len(frames)
    assert all(np.isclose(np.linalg.det(frame.rotation), 1.0) for frame in frames)
    assert frame_candidates("cm", "+z", None) == [InputFrame("cm", "+z", front) for front in ("+x", "-x", "+y", "-y")]


@pytest.mark.parametrize("frame", [InputFrame("mm", "+z", "-y"), InputFrame("cm", "-x", "+y"), InputFrame("m", "+y", "+z")],
                         ids=str)
def test_a_remeshed_body_and_head_in_any_units_and_axes_are_read_in_their_frame(source, heavy_male_remeshed, frame):
    for target in heavy_male_remeshed:
        fit = fit_target_frame(source, written_in(target, frame))
        assert fit.frame == frame, (target.name, fit)
        # the true frame fits within 1 cm on average; the next best is farther
        assert fit.score_m < 0.010 and fit.runner_up_m > 1.05 * fit.score_m


def test_known_parts_are_kept_and_only_the_rest_is_fitted(source, heavy_male_remeshed):
    body, _ = heavy_male_remeshed
    frame = InputFrame("mm", "+z", "-y")
    fit = fit_target_frame(source, written_in(body, frame), units="mm", up="z")
    assert fit.frame == frame
    # a stated wrong front is kept (the caller's word), and fits worse than the true one
    wrong = fit_target_frame(source, written_in(body, frame), units="mm", up="+z", front="+y")
    assert wrong.frame == InputFrame("mm", "+z", "+y") and wrong.score_m > fit.score_m
