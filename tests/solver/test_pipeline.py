"""End-to-end retargeting on MakeHuman characters (paper Table 2's regression tests), and grooms sunk into
toy bodies closed and open, and a body that traps hair (no result with a particle inside)."""

import numpy as np
import pytest

from hairport.solver import pipeline
from hairport.solver.adaptation.segments import MAX_MARGIN
from hairport.solver.mesh.collision import collision_query
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.mesh.segment_crossing import crossing_segments
from hairport.solver.metrics import mean_particle_distance, mean_segment_angle
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError, PenetrationRemaining, TopologyMismatch
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import PRESETS, build_character
from hairport.solver.synthetic.toy import toy_character
from tests.solver.depth_cases import TOY_CHEST_Y_M, chest_cut, keep_faces, sunk, trap
from tests.solver.synthetic.toy_fixtures import PRESET_B


def source_crossing_strands(character, hair) -> np.ndarray:
    """(S,) bool: the strands of ``hair`` with a segment through ``character``'s body as it is."""
    query = collision_query(character.vertices, character.faces, character.name)
    crossing = crossing_segments(hair.points, hair.segments, hair.at_root, query)
    return np.isin(np.arange(hair.n_strands), hair.strand_of[hair.segments[crossing.rows, 0]])


def test_reflexive_retarget_is_exact(female, fringe):
    """A -> A (paper Table 2: 7.85e-8 m, 3.75e-6 rad), but for the strands whose segments dip into the body
    in the groom itself: those are lifted out of it (measured: up to 7.5 mm, next to a root)."""
    result = pipeline.retarget(pipeline.preprocess(female, fringe), female)
    lifted = source_crossing_strands(female, fringe)
    assert 0 < lifted.sum() < 0.2 * fringe.n_strands
    kept = ~lifted[fringe.strand_of]
    distance = mean_particle_distance(result.hair.points[kept], fringe.points[kept])
    segments = fringe.segments[kept[fringe.segments[:, 0]]]
    angle = mean_segment_angle(result.hair.points, fringe.points, segments)
    assert distance <= 1e-7 and angle <= 1e-5, (distance, angle)
    assert np.linalg.norm(result.hair.points - fringe.points, axis=1).max() < MAX_MARGIN
    assert result.solve.converged and result.solve.iterations == 1
    assert result.metrics["penetrating_particles"] == 0 and result.metrics["crossing_segments"]["count"] == 0
    assert result.metrics["root_to_surface_max"] < 1e-12


def test_initial_transfer_to_another_body_keeps_roots_on_it_and_hair_outside(female, fringe):
    male = build_character(PRESETS["heavy-male"])
    adaptable = pipeline.preprocess(female, fringe)
    target = pipeline.prepare_target(adaptable, male)
    initial, _ = pipeline.initial_transfer(adaptable, target)
    query = MeshQuery(male.vertices, male.faces)
    roots = query.signed_distance(initial[fringe.roots]).distance
    assert np.abs(roots).max() < 1e-12
    inside = query.signed_distance(initial[~fringe.is_root]).distance < 0
    # anchoring keeps nearly everything outside; the constrained solve handles the rest
    assert inside.mean() < 0.01, inside.sum()


def test_a_source_without_a_rig_is_anchored_by_its_surface_and_reflexive_retarget_stays_exact(female, fringe):
    bare = Character(female.vertices, female.faces, name="bare")
    adaptable = pipeline.preprocess(bare, fringe)
    assert adaptable.options.anchoring == "surface" and adaptable.bone_names == ()
    result = pipeline.retarget(adaptable, bare)
    kept = ~source_crossing_strands(bare, fringe)[fringe.strand_of]
    assert mean_particle_distance(result.hair.points[kept], fringe.points[kept]) <= 1e-7
    assert result.metrics["fallback_anchors"] == int((~fringe.is_root).sum())
    with pytest.raises(InputError, match="anchor by the surface") as error:
        pipeline.preprocess(bare, fringe, pipeline.PreprocessOptions(anchoring="bones"))
    assert error.value.code == "no_skeleton"


def test_a_hairline_edit_without_rigs_takes_the_head_frame_from_the_mesh_and_lands_near_the_rigged_edit(female, fringe):
    """Source and target without rigs: the preset moves the roots as with the rigs, to within a
    millimetre (the head frames' joints lie 0.3-0.7 cm apart on these bodies)."""
    male = build_character(PRESETS["heavy-male"])
    edit = pipeline.RetargetOptions(hairline=pipeline.HairlineEdit(preset="receding", amount=0.5))
    rigged = pipeline.retarget(pipeline.preprocess(female, fringe), male, edit)
    bare = pipeline.retarget(pipeline.preprocess(Character(female.vertices, female.faces, name="bare"), fringe),
                             Character(male.vertices, male.faces, name="bare-male"), edit)
    assert (rigged.metrics["hairline"]["head_frame"], bare.metrics["hairline"]["head_frame"]) == ("head bone", "mesh")
    assert bare.metrics["anchoring"] == "surface" and bare.metrics["penetrating_particles"] == 0
    assert bare.metrics["hairline"]["roots_moved"] == rigged.metrics["hairline"]["roots_moved"] > 0
    apart = np.linalg.norm(bare.hair.points[fringe.roots] - rigged.hair.points[fringe.roots], axis=1)
    assert apart.mean() < 1e-3 and apart.max() < 3e-3
    travel = rigged.metrics["hairline"]["mean_travel_m"]
    assert abs(bare.metrics["hairline"]["mean_travel_m"] - travel) < 0.1 * travel


def test_another_topology_without_the_wrap_is_refused_by_name_and_a_body_of_another_kind_by_the_wrap(female, fringe):
    adaptable = pipeline.preprocess(female, fringe)
    with pytest.raises(TopologyMismatch, match="topology differs"):
        pipeline.retarget(adaptable, toy_character(), pipeline.RetargetOptions(wrap="off"))
    # the toy character's head is an ellipsoid: the female head does not reach its shape
    with pytest.raises(InputError) as error:
        pipeline.retarget(adaptable, toy_character())
    assert error.value.code == "wrap_failed"


def test_unknown_method_lists_the_valid_ones(female, fringe):
    adaptable = pipeline.preprocess(female, fringe)
    with pytest.raises(InputError, match="global") as error:
        pipeline.retarget(adaptable, female, pipeline.RetargetOptions(method="magic"))
    assert error.value.code == "unknown_method"


@pytest.mark.parametrize("points, offsets", [(np.zeros((0, 3)), [0]), (np.ones((5, 3)), [0, 2, 5])],
                         ids=["no-strand", "zero-length-strands"])
def test_preprocess_refuses_a_hairstyle_without_hair(female, points, offsets):
    with pytest.raises(InputError, match=r"^hair: .*there is no hair to retarget \(code empty_hair\)$") as error:
        pipeline.preprocess(female, pipeline.Hair(points, np.array(offsets)))
    assert error.value.code == "empty_hair"


#: issue 2 asked for 1e-2 rad; with the shape carry (issue 16) the cycle measures 0.0059 rad here
#: (0.71 mm), 0.0124 rad (0.27 mm) without it; issue 16 asks for 0.005 rad (docs/fidelity.md)
CYCLE_ANGLE_BOUND_RAD = 0.01


def test_cycle_a_to_b_to_a(female):
    """A -> B -> A on a clearly different body (1.59 m vs 1.80 m); paper Table 2: 1.97 mm, 4.64e-3 rad."""
    tall = build_character(PRESETS["slim-tall-female"])
    hair = generate_groom(female, "fringe", 60, 64, seed=0)
    there = pipeline.retarget(pipeline.preprocess(female, hair), tall)
    back = pipeline.retarget(pipeline.preprocess(tall, there.hair), female)
    distance = mean_particle_distance(back.hair.points, hair.points)
    angle = mean_segment_angle(back.hair.points, hair.points, hair.segments)
    print(f"cycle: mean distance {distance:.3e} m, mean angle {angle:.3e} rad")
    assert distance <= 3e-3
    assert angle <= CYCLE_ANGLE_BOUND_RAD
    assert back.metrics["penetrating_particles"] == 0


def test_the_metrics_carry_the_input_section_of_the_groom_and_the_target():
    toy = toy_character()
    hair = generate_groom(toy, "short", 30, 6, seed=1)
    plain = pipeline.retarget(pipeline.preprocess(toy, hair), toy, pipeline.RetargetOptions(method="root-translate"))
    assert "input" not in plain.metrics  # nothing was brought into hairport's frame: nothing to say
    adaptable = pipeline.preprocess(toy, hair, input_report={"units": {"hair": "cm"}, "warnings": []})
    result = pipeline.retarget(adaptable, toy, pipeline.RetargetOptions(method="root-translate"),
                               target_input={"units": "cm", "up": "+z"})
    assert result.metrics["input"] == {"units": {"hair": "cm"}, "warnings": [], "target": {"units": "cm", "up": "+z"}}
    assert result.report()["metrics"]["input"]["target"]["up"] == "+z"


@pytest.fixture(scope="module")
def toy_bodies():
    """The toy pair, closed and as busts cut across the chest (the same faces on both)."""
    source, target = toy_character(), toy_character(**PRESET_B, name="toy-b")
    keep = chest_cut(source, TOY_CHEST_Y_M)
    busts = keep_faces(source, keep), keep_faces(target, keep)
    for bust, whole in zip(busts, (source, target)):  # open, from the chest to the crown
        assert not collision_query(bust.vertices, bust.faces).closed
        assert 1.3 < bust.vertices[:, 1].min() < 1.45 and bust.vertices[:, 1].max() == whole.vertices[:, 1].max()
    return {"closed": (source, target), "bust": busts}


@pytest.fixture(scope="module")
def toy_long(toy_bodies):
    return generate_groom(toy_bodies["closed"][0], "long", 100, 16, seed=0)


@pytest.mark.parametrize("depth", [0.03, 0.06])
@pytest.mark.parametrize("body", ["closed", "bust"])
def test_a_groom_sunk_into_its_body_comes_out_whole_on_the_target(toy_bodies, toy_long, body, depth):
    """The groom sunk 3 or 6 cm into a closed body and an open bust: the initial transfer leaves
    over a hundred particles inside, some more than 2 cm deep (which the broad phase used to
    take for far outside: 4 and 36 stayed inside); the result has none, roots exact."""
    source, target = toy_bodies[body]
    hair = sunk(toy_long, depth)
    result = pipeline.retarget(pipeline.preprocess(source, hair), target)
    body_query = collision_query(target.vertices, target.faces)
    initial = body_query.signed_distance(result.initial.points[~hair.is_root]).distance
    assert (initial < 0).sum() > 150 and initial.min() < -0.02, ((initial < 0).sum(), initial.min())
    after = body_query.signed_distance(result.hair.points[~hair.is_root]).distance
    assert (after < 0).sum() == 0 and after.min() >= 5e-4 - 1e-5
    assert result.metrics["penetrating_particles"] == 0 and result.metrics["particles_below_clearance"] == 0
    assert result.metrics["penetration_resolved"] == {"particles": 0, "deepest_m": 0.0}  # the solver got them all
    assert result.metrics["root_to_target_max"] <= 1e-12 and result.metrics["root_to_surface_max"] <= 1e-12
    assert result.solve.converged


def test_particles_a_method_leaves_inside_are_pushed_out_and_reported(toy_bodies, toy_long, monkeypatch):
    """A solver that stops at the initial transfer (sunk 6 cm): the final check pushes every
    particle out and says how many and how deep; nothing is reported with a particle inside."""
    source, target = toy_bodies["bust"]
    hair = sunk(toy_long, 0.06)
    adaptable = pipeline.preprocess(source, hair)
    monkeypatch.setattr(pipeline, "adapt_shape", lambda adaptable, body, initial, *rest, **keywords: (initial.copy(), None))
    result = pipeline.retarget(adaptable, target)
    body = collision_query(target.vertices, target.faces)
    initial = body.signed_distance(result.initial.points[~hair.is_root]).distance
    resolved = result.metrics["penetration_resolved"]
    assert resolved["particles"] == (initial < 0).sum() > 150
    assert resolved["deepest_m"] == pytest.approx(-initial.min(), abs=1e-12) and resolved["deepest_m"] > 0.02
    assert result.metrics["penetrating_particles"] == 0 and result.timings["penetration_check"] > 0


@pytest.mark.parametrize("method", ["multiscale", "global", "root-translate+pushout"])
def test_a_body_that_traps_hair_fails_with_its_code(method):
    """Hair through a stack of plates 10 um apart over the crown (tests/solver/depth_cases.py):
    neither the solve nor the push-out gets it out, and the result is refused."""
    body, hair = trap(toy_character())
    adaptable = pipeline.preprocess(body, hair)
    with pytest.raises(PenetrationRemaining, match=r"^toy-trap: \d+ of the \d+ hair particles .* still inside") as error:
        pipeline.retarget(adaptable, body, pipeline.RetargetOptions(method=method))
    assert error.value.code == "penetration_remaining"
    # the baseline without push-out claims nothing, and reports its penetration
    plain = pipeline.retarget(adaptable, body, pipeline.RetargetOptions(method="root-translate"))
    assert plain.metrics["penetrating_particles"] > 20 and "penetration_resolved" not in plain.metrics


def test_every_report_counts_the_segments_that_pass_through_the_body(female, fringe):
    """A baseline that ignores the body leaves segments through it: the report's count is the exact test's."""
    from hairport.solver.mesh.segment_crossing import crossing_segments

    heavy = build_character(PRESETS["heavy-male"])
    result = pipeline.retarget(pipeline.preprocess(female, fringe), heavy,
                               pipeline.RetargetOptions(method="root-translate"))
    body = collision_query(heavy.vertices, heavy.faces)
    expected = crossing_segments(result.hair.points, fringe.segments, fringe.at_root, body)
    report = result.metrics["crossing_segments"]
    assert report["count"] == expected.count > 0
    assert report["deepest_m"] == pytest.approx(expected.depth.max()) and report["deepest_m"] > 0
    strand, segment = report["deepest_strand"], report["deepest_segment"]
    assert 0 <= segment < fringe.counts[strand] - 1
