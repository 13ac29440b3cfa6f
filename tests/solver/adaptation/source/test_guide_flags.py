"""Guides flagged by a per-strand attribute, and guides written as flags."""

import numpy as np
import pytest

from hairport.solver.adaptation.source.guide_flags import flagged_guides, with_guide_flags
from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import Hair, HairAttribute


def hair_with(**attributes) -> Hair:
    return Hair(np.arange(18.0).reshape(6, 3), [0, 2, 4, 6], attributes=attributes)


def test_flagged_strands_are_the_guides_and_flags_written_back_read_the_same():
    hair = hair_with(groom_guide=HairAttribute(np.array([0, 3, 1], np.int16), "strand"))
    assert flagged_guides(hair).tolist() == [1, 2]
    flagged = with_guide_flags(hair_with(), np.array([0, 2]))
    assert flagged.attributes["groom_guide"].values.dtype == np.int16
    assert flagged_guides(flagged).tolist() == [0, 2]


@pytest.mark.parametrize("attributes, code, words", [
    ({}, "no_guide_flags", "no per-strand attribute"),
    ({"groom_guide": HairAttribute(np.zeros(6), "vertex")}, "no_guide_flags", "no per-strand attribute"),
    ({"groom_guide": HairAttribute(np.zeros(3), "strand")}, "no_guide_flags", "flags no strand"),
    ({"groom_guide": HairAttribute(np.ones(3), "strand")}, "too_large", "flags 3 guides, more than the 2"),
])
def test_missing_or_empty_flags_are_refused(attributes, code, words):
    with pytest.raises(InputError, match=words) as caught:
        flagged_guides(hair_with(**attributes), max_guides=2)
    assert caught.value.code == code
