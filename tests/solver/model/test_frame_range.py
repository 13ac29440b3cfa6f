"""Frame ranges ``START:END[:STEP]``: both ends included, time codes with decimals, indices into a list of meshes;
malformed or absurd ranges refused with ``bad_frames``."""

from __future__ import annotations

import numpy as np
import pytest

from hairport.solver.model.errors import InputError
from hairport.solver.model.frame_range import MAX_FRAMES, FrameRange


@pytest.mark.parametrize("text, times", [
    ("0:48", np.arange(49.0)),
    ("1001:1007:2", [1001.0, 1003.0, 1005.0, 1007.0]),
    (" 3 : 3 ", [3.0]),
    ("0:1:0.25", [0.0, 0.25, 0.5, 0.75, 1.0]),
    ("-2:2:2", [-2.0, 0.0, 2.0]),
    ("0:10:4", [0.0, 4.0, 8.0]),
])
def test_a_range_holds_both_ends_on_its_step(text, times):
    frames = FrameRange.parse(text)
    assert np.array_equal(frames.times(), times) and frames.count() == len(times)


@pytest.mark.parametrize("text", ["", "0", "0:", "a:b", "0:10:0", "10:0", "0:10:-1", "0:1e9", "0:10:2:3", "nan:1"])
def test_malformed_or_absurd_ranges_are_refused(text):
    with pytest.raises(InputError) as caught:
        FrameRange.parse(text)
    assert caught.value.code == "bad_frames"


def test_a_range_too_long_is_refused_by_its_count():
    with pytest.raises(InputError) as caught:
        FrameRange.parse(f"0:{MAX_FRAMES}")
    assert caught.value.code == "bad_frames" and f"{MAX_FRAMES + 1:,}" in caught.value.problem
    assert FrameRange.parse(f"0:{MAX_FRAMES - 1}").count() == MAX_FRAMES


def test_a_list_of_meshes_is_picked_by_whole_indices_within_it():
    assert np.array_equal(FrameRange.parse("1:5:2").pick(6), [1, 3, 5])
    for text, count, word in (("0:6", 6, "6 frames"), ("0:2:0.5", 6, "whole numbers"), ("-1:2", 6, "6 frames")):
        with pytest.raises(InputError) as caught:
            FrameRange.parse(text).pick(count)
        assert caught.value.code == "bad_frames" and word in caught.value.problem
