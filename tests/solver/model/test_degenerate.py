"""Degenerate pieces of a groom (solver/model/degenerate.py, solver/model/hair.py): what counts as which kind."""

import numpy as np
import pytest

from hairport.solver.model.degenerate import (
    STRAY_SIZES,
    STRAY_STRANDS,
    degenerate_report,
    duplicate_strands,
    require_no_stray_strands,
    strand_lengths,
    stray_strands,
)
from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import DEGENERATE_SEGMENT_M, EMPTY_HAIR, Hair, require_hair


def straight(root, n=5, step=0.01, direction=(0.0, -1.0, 0.0)) -> np.ndarray:
    """``n`` points from ``root`` along ``direction``, ``step`` m apart."""
    return np.asarray(root, dtype=float) + step * np.arange(n)[:, None] * np.asarray(direction)


def groom(n=10) -> list[np.ndarray]:
    """``n`` straight strands 1 cm apart along x."""
    return [straight((0.01 * s, 1.6, 0.0)) for s in range(n)]


def test_short_segments_and_particles_at_the_root():
    strands = groom(4)
    strands[1] = np.repeat(strands[1][:1], 5, axis=0)  # collapsed
    strands[2] = np.insert(strands[2], 0, strands[2][0], axis=0)  # a repeated root point
    strands[2] = np.insert(strands[2], 4, strands[2][4] + 1e-12, axis=0)  # a 1e-12 m segment inside
    hair = Hair.from_strands(strands)
    short = hair.short_segments
    assert short.sum() == 4 + 2  # the collapsed strand's four, the strand's two
    assert short[hair.offsets[2]] and short[hair.offsets[2] + 4] and not short[hair.offsets[2] + 1]
    at_root = hair.at_root
    # the roots, the collapsed strand's five particles, the repeated root point: 4 + 4 + 1
    assert at_root.sum() == 4 + 4 + 1
    assert at_root[hair.offsets[1]:hair.offsets[2]].all() and at_root[hair.offsets[2] + 1]
    assert not at_root[hair.offsets[2] + 5]  # welded to a particle that is not at the root
    assert hair.collapsed.tolist() == [False, True, False, False]
    # a segment just longer than the degenerate length is an ordinary one
    nearly = Hair.from_strands([straight((0, 0, 0), 3, 1.01 * DEGENERATE_SEGMENT_M), straight((0.01, 0, 0))])
    assert not nearly.short_segments.any() and not nearly.collapsed.any()


def test_place_at_roots_moves_the_welded_particles_onto_their_moved_root():
    strands = groom(3)
    strands[0] = np.repeat(strands[0][:1], 4, axis=0)
    hair = Hair.from_strands(strands)
    moved = hair.points + np.array([0.1, 0.2, 0.3])
    moved[hair.offsets[0] + 1:hair.offsets[1]] = 7.0  # wherever a transfer put them
    placed = hair.place_at_roots(moved.copy())
    np.testing.assert_array_equal(placed[:4], np.repeat(moved[:1], 4, axis=0))
    np.testing.assert_array_equal(placed[4:], moved[4:])


def test_require_hair_counts_degenerate_strands_as_empty_in_meters():
    tiny = [straight((0.01 * s, 0, 0), 4, 1e-9) for s in range(3)]
    require_hair(Hair.from_strands(tiny).points, Hair.from_strands(tiny).offsets)  # in a file's units: not equal
    with pytest.raises(InputError) as refused:
        hair = Hair.from_strands(tiny)
        require_hair(hair.points, hair.offsets, "hair", DEGENERATE_SEGMENT_M)
    assert refused.value.code == EMPTY_HAIR and "3" in refused.value.problem


def test_duplicate_strands_are_the_later_copies_point_for_point():
    strands = groom(6)
    strands.append(strands[2].copy())
    strands.append(strands[2].copy())
    near_copy = strands[4].copy()
    near_copy[2, 0] += 1e-12  # same root, tip and count, one point apart: no duplicate
    strands.append(near_copy)
    hair = Hair.from_strands(strands)
    assert np.flatnonzero(duplicate_strands(hair.points, hair.offsets)).tolist() == [6, 7]
    assert not duplicate_strands(hair.points[:0], np.array([0])).any()


def test_strand_lengths_are_summed_strand_by_strand():
    strands = groom(3)
    strands.insert(1, straight((1e37, 0, 0), 3, 1e36))
    hair = Hair.from_strands(strands)
    lengths = strand_lengths(hair.points, hair.offsets)
    np.testing.assert_allclose(lengths[[0, 2, 3]], 0.04, rtol=1e-12)  # not swallowed by the 1e37 before them
    assert lengths[1] == pytest.approx(2e36)


@pytest.mark.parametrize("shift", [5.0, 1e3, 3e38])
def test_a_strand_far_from_the_rest_is_stray_in_any_units(shift):
    strands = groom(10)
    strands.insert(4, strands[4] + np.array([0.0, shift, 0.0]))
    hair = Hair.from_strands(strands)
    stray, reach, size = stray_strands(hair.points, hair.offsets)
    assert np.flatnonzero(stray).tolist() == [4]
    assert reach[4] > STRAY_SIZES and reach[np.arange(11) != 4].max() < 2.0
    # the same groom in millimetres: the same answer
    scaled, _, scaled_size = stray_strands(hair.points * 1000.0, hair.offsets)
    assert scaled.tolist() == stray.tolist() and scaled_size == pytest.approx(1000.0 * size)
    with pytest.raises(InputError) as refused:
        require_no_stray_strands(hair.points, hair.offsets, "hair")
    assert refused.value.code == STRAY_STRANDS
    assert "1 of 11 strands" in refused.value.problem and "strand(s) 4:" in refused.value.problem


def test_long_hair_is_not_stray():
    strands = groom(10)
    strands[3] = straight(strands[3][0], 50, 0.04)  # 2 m of hair among 4 cm strands
    hair = Hair.from_strands(strands)
    assert not stray_strands(hair.points, hair.offsets)[0].any()
    require_no_stray_strands(hair.points, hair.offsets)
    one = Hair.from_strands([np.zeros((3, 3))])  # no size: nothing to compare with
    assert not stray_strands(one.points, one.offsets)[0].any()


def test_degenerate_report_names_counts_and_first_strands():
    strands = groom(12)
    for s in (3, 5, 6, 7, 8, 9, 10):
        strands[s] = np.repeat(strands[s][:1], 5, axis=0)
    strands[1] = np.insert(strands[1], 2, strands[1][2], axis=0)
    strands.append(strands[0].copy())
    report, notes = degenerate_report(Hair.from_strands(strands))
    assert report["collapsed_strands"] == {"count": 7, "strands": [3, 5, 6, 7, 8]}
    assert report["zero_length_segments"] == {"count": 1, "strand_count": 1, "strands": [1]}
    # the collapsed strands are copies of one another only if they sit at one place: these do not
    assert report["duplicate_strands"] == {"count": 1, "strands": [12]}
    assert any(note.startswith("7 of 13 strands have zero length") and "3, 5, 6, 7, 8, ..." in note for note in notes)
    assert any("1 segment(s) of zero length" in note and "(1)" in note for note in notes)
    assert any("1 strand(s) repeat an earlier strand" in note and "(12)" in note for note in notes)
    clean_report, clean_notes = degenerate_report(Hair.from_strands(groom(3)))
    assert clean_notes == [] and clean_report["collapsed_strands"]["count"] == 0
