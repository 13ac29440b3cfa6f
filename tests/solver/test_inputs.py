"""Tests for solver/inputs.py: inputs in any units and axes brought into hairport's frame, refused when
the groom does not sit on its body, the input report, and results and curves written back."""

import numpy as np
import pytest

from hairport.solver.hairline.curve import HairlineCurve
from hairport.solver.hairline.edit import HairlineEdit
from hairport.solver.inputs import (
    HEAD_FIT_M,
    OTHER_TOPOLOGY_HOW,
    ROOT_OFF_SURFACE_MM,
    canonical_source,
    canonical_target,
    edit_in_canonical,
    hair_in_frame,
    measure_groom,
)
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError
from hairport.solver.model.frame import InputFrame
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import PRESETS, build_character
from hairport.solver.synthetic.remesh import head_cut, neck_height, remeshed_character
from tests.solver.frames import character_in, hair_in

N_STRANDS = 120


@pytest.fixture(scope="module")
def groom(toy_a, query_a):
    return generate_groom(toy_a, "short", N_STRANDS, 8, seed=6, query=query_a)


@pytest.mark.parametrize("frame", [InputFrame("mm", "z", "-y"), InputFrame("cm", "x", "z"), InputFrame("m", "-y", "z"),
                                   InputFrame("dm", "y", "z")])
def test_a_source_in_other_units_and_axes_comes_back_to_hairports_frame(toy_a, groom, frame):
    inputs = canonical_source(character_in(frame, toy_a), hair_in(frame, groom))
    assert inputs.frame == frame
    scale = np.abs(toy_a.vertices).max()
    assert np.abs(inputs.source.vertices - toy_a.vertices).max() <= 4e-16 * scale
    assert np.abs(inputs.source.skeleton.tails - toy_a.skeleton.tails).max() <= 4e-16 * scale
    assert np.abs(inputs.hair.points - groom.points).max() <= 4e-16 * scale
    report = inputs.report
    assert report["units"] == {"hair": frame.units, "source": frame.units, "how": report["units"]["how"]}
    assert report["units"]["how"].startswith(f"inferred from sizes: in {frame.units} the body is 0.61 m")
    assert (report["axes"]["up"], report["axes"]["front"], report["axes"]["up_how"]) == (frame.up, frame.front,
                                                                                          "the head bone")
    assert report["bounding_boxes"]["hair"]["units"] == frame.units
    assert np.allclose(report["bounding_boxes"]["hair"]["max"], hair_in(frame, groom).points.max(axis=0), atol=1e-9)
    assert inputs.warnings == () and report["warnings"] == []
    assert f"input: units {frame.units} (inferred from sizes" in inputs.summary()
    out = hair_in_frame(inputs.frame, inputs.hair)
    assert np.abs(out.points / frame.scale - hair_in(frame, groom).points).max() <= 1e-12 * scale / frame.scale


def test_hair_in_millimetres_on_a_body_in_meters_is_refused_naming_the_units(toy_a, groom):
    with pytest.raises(InputError) as error:
        canonical_source(character_in(InputFrame(), toy_a), hair_in(InputFrame("mm"), groom))
    assert error.value.code == "units_mismatch"
    message = str(error.value)
    assert "with the hair in mm and the body in m they sit on it" in message and "--hair-units mm --units m" in message
    # the body's units stated (a sidecar, glTF): the hair's are inferred from where its roots sit
    inputs = canonical_source(toy_a, hair_in(InputFrame("mm"), groom), source_units="m")
    assert inputs.frame.units == "mm" and inputs.report["units"]["how"].startswith("inferred for the hair: read in mm")
    assert np.abs(inputs.hair.points - groom.points).max() < 1e-15 * 2
    # the hair's stated, the body's inferred
    inputs = canonical_source(character_in(InputFrame("cm"), toy_a), groom, hair_units="m")
    assert (inputs.frame.units, inputs.report["units"]["source"]) == ("m", "cm")
    assert np.abs(inputs.source.vertices - toy_a.vertices).max() < 1e-15 * 2
    # stated units that do not fit are refused too, naming the ones that do
    with pytest.raises(InputError) as error:
        canonical_source(toy_a, hair_in(InputFrame("cm"), groom), source_units="m", hair_units="m")
    assert error.value.code == "units_mismatch" and "--hair-units cm;" in str(error.value)


def test_a_groom_that_sits_on_no_body_in_any_units_is_refused(toy_a, groom):
    with pytest.raises(InputError) as error:
        canonical_source(toy_a, groom.with_points(groom.points + [3.0, 0.0, 0.0]))
    assert error.value.code == "hair_off_body" and "median 2.8" in str(error.value)


def moved_along_root_normals(query, hair, distance):
    """Every strand moved rigidly by ``distance`` along the outward normal at its root."""
    normals = query.signed_distance(hair.points[hair.roots]).normal
    return hair.with_points(hair.points + distance * np.repeat(normals, hair.counts, axis=0))


def test_the_input_section_measures_a_groom_sunk_2_mm_and_one_lifted_4_mm(toy_a, query_a, groom):
    measured, notes = measure_groom(toy_a, groom, query_a)
    assert measured["source_penetration"] == {"particles": 0, "deepest_m": 0.0} and notes == []
    assert measured["root_distance_m"]["max"] < 1e-6 and measured["root_distance_m"]["off_surface"] == 0

    sunk, notes = measure_groom(toy_a, moved_along_root_normals(query_a, groom, -0.002), query_a)
    roots = sunk["root_distance_m"]
    assert 1.9e-3 < roots["mean"] <= 2.0e-3 + 1e-9 and roots["max"] <= 2.0e-3 + 1e-9
    assert roots["off_surface"] == roots["inside"] == N_STRANDS and roots["tolerance_mm"] == ROOT_OFF_SURFACE_MM
    # the groom's second particles sit 4.3 mm or more off the skin: 2 mm under, only the roots are in
    assert sunk["source_penetration"] == {"particles": 0, "deepest_m": 0.0}
    assert notes == [f"{N_STRANDS} of {N_STRANDS} roots sit more than 1 mm off the source body (mean 2.00 mm, "
                     "largest 2.00 mm); each is anchored at its closest point on the body"]
    deeper, notes = measure_groom(toy_a, moved_along_root_normals(query_a, groom, -0.01), query_a)
    inside = deeper["source_penetration"]
    assert inside["particles"] > groom.n_particles / 2 and 0.004 < inside["deepest_m"] < 0.01, inside
    assert len(notes) == 2 and notes[1].startswith(f"{inside['particles']} of {groom.n_particles} hair particles")

    inputs = canonical_source(toy_a, moved_along_root_normals(query_a, groom, 0.004), source_units="m",
                              hair_units="m")
    lifted = inputs.report["root_distance_m"]
    assert 3.9e-3 < lifted["mean"] <= 4.0e-3 + 1e-9 and lifted["max"] <= 4.0e-3 + 1e-9
    assert lifted["off_surface"] == N_STRANDS and lifted["inside"] == 0
    assert inputs.report["source_penetration"]["particles"] == 0
    assert len(inputs.warnings) == 1 and "(mean 4.00 mm, largest 4.00 mm)" in inputs.warnings[0]
    assert inputs.report["warnings"] == list(inputs.warnings)


def test_weights_a_sidecar_lacks_are_derived_in_meters_after_the_units_are_known(toy_a, groom):
    bare = Character(toy_a.vertices * 1000.0, toy_a.faces, toy_a.skeleton.scaled(1000.0), None, "mm")
    inputs = canonical_source(bare, hair_in(InputFrame("mm"), groom))
    reference = canonical_source(Character(toy_a.vertices, toy_a.faces, toy_a.skeleton, None), groom)
    assert inputs.source.weights is not None
    assert abs(inputs.source.weights - reference.source.weights).max() < 1e-9


def test_a_target_takes_the_sources_units_and_axes_unless_it_states_them(toy_a, toy_b):
    frame = InputFrame("mm", "z", "-y")
    target, found = canonical_target(toy_a, character_in(frame, toy_b))
    assert np.abs(target.vertices - toy_b.vertices).max() <= 4e-16 * 2
    assert (found["units"], found["up"], found["front"]) == ("mm", "+z", "-y")
    assert found["units_how"] == "inferred: the source's size" and found["axes_how"].startswith("fitted")
    assert 0.9 < found["size_ratio_to_source"] < 1.1 and found["bounding_box"]["units"] == "mm"
    given, found = canonical_target(toy_a, character_in(InputFrame(up="x", front="z"), toy_b), units="m", up="x",
                                    front="z")
    assert np.array_equal(given.vertices, toy_b.vertices) and found["axes_how"] == "given"
    assert found["topology"] == "same" and "head_fit_mm" not in found
    with pytest.raises(InputError) as error:
        canonical_target(toy_a, character_in(InputFrame("cm"), toy_b), units="m")
    assert error.value.code == "units_mismatch" and "looks like it is in cm" in str(error.value)


@pytest.fixture(scope="module")
def female():
    return build_character(PRESETS["average-female"])


@pytest.fixture(scope="module")
def male_and_head():
    """The heavy male remeshed to 5,000 vertices (another topology than the female's) and his head cut at the
    neck (canonical, meters)."""
    male = build_character(PRESETS["heavy-male"])
    body = remeshed_character(male, 5000, seed=2)
    return body, head_cut(body, neck_height(male))[0]


@pytest.mark.parametrize("part", [0, 1], ids=["body", "head"])
def test_a_target_of_another_topology_takes_the_frame_its_head_fits(female, male_and_head, part):
    target = male_and_head[part]
    frame = InputFrame("mm", "z", "-y")
    canonical, found = canonical_target(female, character_in(frame, target))
    assert np.abs(canonical.vertices - target.vertices).max() < 1e-12
    assert (found["units"], found["up"], found["front"], found["topology"]) == ("mm", "+z", "-y", "other")
    assert found["units_how"] == found["axes_how"] == OTHER_TOPOLOGY_HOW
    assert 0.0 < found["axes_confidence"] < 1.0 and found["head_fit_mm"] < 1e3 * HEAD_FIT_M
    # a head alone is a fraction of the full-body source: no size check between topologies
    assert (found["size_ratio_to_source"] < 0.3) == (part == 1)
    assert found["bounding_box"]["units"] == "mm"
    assert np.allclose(found["bounding_box"]["max"], character_in(frame, target).vertices.max(axis=0), atol=1e-6)


def test_what_is_given_for_another_topology_is_kept_and_wrong_units_are_refused(female, male_and_head):
    head = male_and_head[1]
    frame = InputFrame("cm", "-x", "y")
    in_meters = character_in(InputFrame("m", "-x", "y"), head)  # read in its stated units: meters
    canonical, found = canonical_target(female, in_meters, units="cm")
    assert np.abs(canonical.vertices - head.vertices).max() < 1e-12
    assert (found["units"], found["units_how"], found["axes_how"]) == ("cm", "given or stated by the file",
                                                                       OTHER_TOPOLOGY_HOW)
    assert np.allclose(found["bounding_box"]["max"], character_in(frame, head).vertices.max(axis=0), atol=1e-9)
    given, found = canonical_target(female, in_meters, units="cm", up="-x", front="y")
    assert np.array_equal(given.vertices, canonical.vertices)
    assert (found["axes_how"], found["axes_confidence"]) == ("given", 1.0)
    # a file in millimetres said to be in centimetres: its head is ten times a head's size
    in_file = character_in(InputFrame("mm", "-x", "y"), head)
    with pytest.raises(InputError) as error:
        canonical_target(female, Character(in_file.vertices * 0.01, in_file.faces, name="head.obj"), units="cm")
    assert error.value.code == "units_mismatch" and error.value.source == "head.obj"
    assert "not a head's size in its units cm" in str(error.value) and "give its units as mm" in str(error.value)


def test_a_hairline_curve_drawn_in_the_grooms_axes_comes_to_hairports_frame():
    frame = InputFrame("mm", "z", "-y")
    points = np.array([[0.1, 1.6, 0.05], [0.0, 1.7, 0.09], [-0.1, 1.6, 0.05]])
    curve = HairlineCurve(frame.axes_out(points), np.array([1]))
    edit = edit_in_canonical(frame, HairlineEdit(curve=curve))
    assert np.array_equal(edit.curve.points, points) and np.array_equal(edit.curve.turning_points, [1])
    preset = HairlineEdit(preset="round")
    assert edit_in_canonical(frame, preset) is preset and edit_in_canonical(frame, None) is None
