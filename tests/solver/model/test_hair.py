"""The hairstyle container: CSR strands, derived indices, subsets, and the layout check."""

import numpy as np
import pytest

from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import Hair, HairAttribute, particle_indices, require_hair, validate_layout


@pytest.fixture
def hair() -> Hair:
    return Hair.from_strands([np.arange(9.0).reshape(3, 3), 10 + np.arange(6.0).reshape(2, 3),
                              20 + np.arange(12.0).reshape(4, 3)])


def test_layout_indices(hair):
    assert (hair.n_strands, hair.n_particles) == (3, 9)
    assert hair.counts.tolist() == [3, 2, 4] and hair.roots.tolist() == [0, 3, 5]
    assert hair.strand_of.tolist() == [0, 0, 0, 1, 1, 2, 2, 2, 2]
    assert hair.is_root.tolist() == [True, False, False, True, False, True, False, False, False]
    assert hair.index_in_strand.tolist() == [0, 1, 2, 0, 1, 0, 1, 2, 3]
    assert hair.segments.tolist() == [[0, 1], [1, 2], [3, 4], [5, 6], [6, 7], [7, 8]]
    np.testing.assert_array_equal(hair.strand(1), 10 + np.arange(6.0).reshape(2, 3))


def test_subsets_keep_attributes(hair):
    styled = Hair(hair.points, hair.offsets, thickness=np.arange(9.0), color=np.ones((9, 3)) * 0.5)
    part = styled.subset(np.array([2, 0]))
    assert part.counts.tolist() == [4, 3] and part.thickness.tolist() == [5, 6, 7, 8, 0, 1, 2]
    assert particle_indices(hair.offsets, np.array([2, 0])).tolist() == [5, 6, 7, 8, 0, 1, 2]
    moved = styled.with_points(styled.points + 1)
    assert moved.thickness is styled.thickness and moved.points[0, 0] == 1.0


def test_bad_attributes_are_refused(hair):
    with pytest.raises(InputError, match=r"thickness has shape \(2,\), expected \(9,\)"):
        Hair(hair.points, hair.offsets, thickness=np.ones(2))
    with pytest.raises(InputError, match=r"color has shape \(9,\), expected \(9, 3\)"):
        Hair(hair.points, hair.offsets, color=np.ones(9))


@pytest.mark.parametrize("points, offsets, code", [
    (np.zeros((4, 2)), np.array([0, 4]), "bad_shape"),
    (np.zeros((4, 3)), np.zeros((1, 2), dtype=np.int64), "bad_shape"),
    (np.zeros((4, 3)), np.array([1, 4]), "bad_offsets"),
    (np.zeros((4, 3)), np.array([0, 3]), "bad_offsets"),
    (np.zeros((4, 3)), np.array([0, 3, 4]), "short_strand"),
    (np.array([[0, 0, 0], [0, np.inf, 0.0]]), np.array([0, 2]), "non_finite"),
])
def test_layout_check(points, offsets, code):
    with pytest.raises(InputError) as refused:
        validate_layout(points, offsets, "groom.data")
    assert refused.value.code == code and str(refused.value).startswith("groom.data: ")


def test_an_empty_hairstyle_passes_the_layout_check():
    validate_layout(np.zeros((0, 3)), np.array([0]))
    assert Hair.from_strands([]).n_strands == 0


def test_require_hair_refuses_no_strand_and_zero_length_strands_only():
    with pytest.raises(InputError, match=r"^g\.data: no strand of two or more points") as error:
        require_hair(np.zeros((0, 3)), np.array([0]), "g.data")
    assert error.value.code == "empty_hair"
    with pytest.raises(InputError, match=r"every strand \(2\) has zero length") as error:
        require_hair(np.ones((5, 3)), np.array([0, 2, 5]))
    assert error.value.code == "empty_hair"
    # strand 0 ends where strand 1 starts 1 m away: that jump is no segment, both strands are flat
    with pytest.raises(InputError, match="zero length"):
        require_hair(np.array([[0.0, 0, 0], [0, 0, 0], [1, 0, 0], [1, 0, 0]]), np.array([0, 2, 4]))
    require_hair(np.array([[0.0, 0, 0], [0, 0, 0], [1, 0, 0], [1, 0, 1e-9]]), np.array([0, 2, 4]))


def _two_strands() -> Hair:
    return Hair(np.arange(15.0).reshape(5, 3), [0, 2, 5])


def test_attributes_follow_subsets_and_new_points():
    base = _two_strands()
    attributes = {"uv": HairAttribute(np.arange(10.0).reshape(5, 2), "vertex", "texcoord"),
                  "group": HairAttribute(np.array([4, 9], np.int16), "strand")}
    hair = Hair(base.points, base.offsets, attributes=attributes)
    part = hair.subset(np.array([1, 0]))
    np.testing.assert_array_equal(part.attributes["uv"].values, [[4, 5], [6, 7], [8, 9], [0, 1], [2, 3]])
    np.testing.assert_array_equal(part.attributes["group"].values, [9, 4])
    assert part.attributes["group"].values.dtype == np.int16 and part.attributes["uv"].role == "texcoord"
    moved = hair.with_points(hair.points + 1)
    assert moved.attributes["uv"] is hair.attributes["uv"]
    assert list(hair.attributes_of("strand")) == ["group"] and hair.without_attributes().attributes == {}


@pytest.mark.parametrize("name, attribute, words", [
    ("bad name", HairAttribute(np.zeros(5), "vertex"), "not a name"),
    ("uv", HairAttribute(np.zeros(4), "vertex"), "expected (5,)"),
    ("group", HairAttribute(np.zeros(5), "strand"), "expected (2,)"),
    ("wide", HairAttribute(np.zeros((2, 17)), "strand"), "at most 16"),
    ("cube", HairAttribute(np.zeros((2, 2, 2)), "strand"), "has shape (2, 2, 2)"),
    ("nan", HairAttribute(np.array([0.0, np.nan]), "strand"), "non-finite value (NaN or inf) in row 1"),
    ("text", HairAttribute(np.array(["a", "b"]), "strand"), "<U1 values"),
])
def test_attributes_that_do_not_fit_the_hairstyle_are_refused(name, attribute, words):
    base = _two_strands()
    with pytest.raises(InputError) as caught:
        Hair(base.points, base.offsets, attributes={name: attribute})
    assert caught.value.code == "bad_attribute" and words in str(caught.value)


def test_an_attribute_names_its_domain_and_role_from_fixed_lists():
    with pytest.raises(ValueError, match="domain 'edge'"):
        HairAttribute(np.zeros(2), "edge")
    with pytest.raises(ValueError, match="role 'colour'"):
        HairAttribute(np.zeros(2), "strand", "colour")
    big_endian = HairAttribute(np.arange(3, dtype=">i4"), "strand")
    assert big_endian.values.dtype == np.dtype("=i4") and big_endian.values.tolist() == [0, 1, 2]
