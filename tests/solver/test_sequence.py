"""A hairstyle onto a sequence of bodies: warm frames land where cold retargets do, with nothing inside the body and
no popping; the temporal term is Eq. 11 split between two anchors; the coherence figures; refused sequences."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hairport import solver
from hairport.solver import sequence
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError
from hairport.solver.options import SequenceOptions
from hairport.solver.pipeline import PreviousFrame, temporal_anchor
from hairport.solver.sequence import JUMP_ALLOWANCE_M, body_motion_near_hair, frame_coherence, require_one_topology
from hairport.solver.synthetic import toy
from hairport.solver.synthetic.groom import generate_groom
from tests.solver.synthetic.toy_fixtures import PRESET_B

#: frames of the toy sweep (the source's body, then steps toward the other toy body)
SWEEP_FRAMES = 5


@pytest.fixture(scope="module")
def sweep():
    """The toy body swept in straight vertex steps to a larger head and wider shoulders (0.4-0.7 cm a step near the
    hair), a groom on it, and every frame retargeted cold and in sequence."""
    source = toy.toy_character(name="source")
    other = toy.toy_character(**PRESET_B, name="other")
    frames = [Character(source.vertices + t * (other.vertices - source.vertices), source.faces, name=f"frame {i}")
              for i, t in enumerate(np.linspace(0.0, 1.0, SWEEP_FRAMES))]
    adaptable = solver.preprocess(source, generate_groom(source, "long", 120, 16, seed=1),
                                  solver.PreprocessOptions(guides=30))
    cold = [solver.retarget(adaptable, frame) for frame in frames]
    warm = list(sequence.retarget_sequence(adaptable, frames))
    return {"frames": frames, "adaptable": adaptable, "cold": cold, "warm": warm}


def test_the_first_frame_is_a_cold_retarget_and_later_ones_stay_near_theirs(sweep):
    cold, warm = sweep["cold"], sweep["warm"]
    assert np.array_equal(warm[0].hair.points, cold[0].hair.points)
    for number, (w, c) in enumerate(zip(warm, cold)):
        assert w.metrics["frame"] == number and w.metrics["penetrating_particles"] == 0
        assert w.metrics["crossing_segments"]["count"] == 0
        mean = np.linalg.norm(w.hair.points - c.hair.points, axis=1).mean()
        assert mean < 5e-4, (number, mean)
    assert max(np.linalg.norm(w.hair.points - c.hair.points, axis=1).mean() for w, c in zip(warm[1:], cold[1:])) > 0


def test_warm_frames_start_from_the_carried_result_and_stop_the_coarse_level_at_their_step(sweep):
    from hairport.solver.pipeline import WARM_COARSE_STEP_M

    for result in sweep["warm"][1:]:
        steps = result.solve.coarse.max_step  # each iteration's longest guide particle move (m)
        assert steps[-1] < WARM_COARSE_STEP_M <= min(steps[:-1], default=np.inf), steps
    assert sweep["cold"][2].solve.coarse.iterations > sweep["warm"][2].solve.coarse.iterations
    # the roots sit on the frame's scalp, as a cold retarget puts them
    hair = sweep["adaptable"].hair
    for w, c in zip(sweep["warm"], sweep["cold"]):
        assert np.abs(w.hair.points[hair.roots] - c.hair.points[hair.roots]).max() < 1e-9
    # the next frame's body query is the previous one's moved: its face search refit, not built; the frames hand
    # their queries on and keep none (a single retarget keeps none either)
    trees = []
    for result in sequence.retarget_sequence(sweep["adaptable"], sweep["frames"][:2]):
        trees.append(result.queries[0]._closest._tree)
    assert trees[1].child is trees[0].child and not np.array_equal(trees[1].boxes, trees[0].boxes)
    assert all(result.queries is None for result in sweep["warm"] + sweep["cold"])


def test_no_frame_pops(sweep):
    for result in sweep["warm"][1:]:
        coherence = result.metrics["coherence"]
        assert 0.003 < coherence["body_motion_near_hair_m"] < 0.03
        assert coherence["largest_jump_m"] <= coherence["jump_bound_m"] and not coherence["pops"]
        assert coherence["particles_beyond"] == 0
        assert coherence["jump_bound_m"] == pytest.approx(2 * coherence["body_motion_near_hair_m"] + JUMP_ALLOWANCE_M)


def test_the_report_sums_up_the_frames(sweep):
    report = sequence.sequence_report(sweep["warm"], [10.0, 11.0, 12.0, 13.0, 14.0])
    summary = report["summary"]
    assert summary["frames"] == SWEEP_FRAMES and summary["penetrating_particles_max"] == 0
    assert summary["frames_that_pop"] == 0
    assert summary["largest_jump_m"] == max(r.metrics["coherence"]["largest_jump_m"] for r in sweep["warm"][1:])
    assert [frame["time"] for frame in report["frames"]] == [10.0, 11.0, 12.0, 13.0, 14.0]
    assert summary["first_frame_s"] == sweep["warm"][0].timings["frame"] > 0
    records = [sequence.FrameRecord.of(result) for result in sweep["warm"]]
    assert sequence.sequence_report(records, [10.0, 11.0, 12.0, 13.0, 14.0]) == report


def test_a_temporal_term_pulls_each_frame_toward_the_previous_one(sweep):
    adaptable, frames = sweep["adaptable"], sweep["frames"]
    previous = sweep["warm"][2]
    free = solver.retarget(adaptable, frames[3], previous=previous.as_previous())
    held = solver.retarget(adaptable, frames[3], previous=previous.as_previous(), temporal=1e5)
    carried = previous.as_previous().carried(held.base)
    gap = {name: np.linalg.norm(result.hair.points - carried, axis=1).mean() for name, result in
           (("free", free), ("held", held))}
    assert gap["held"] < 0.3 * gap["free"], gap
    assert held.metrics["penetrating_particles"] == 0


def test_the_temporal_term_joins_eq_11_exactly():
    rng = np.random.default_rng(0)
    initial, carried = rng.normal(size=(2, 7, 3))
    beta, temporal = 1e3, 3e3
    anchor, weight = temporal_anchor(initial, carried, beta, temporal)
    assert weight == beta + temporal

    def difference(p):
        return beta * ((p - initial) ** 2).sum() + temporal * ((p - carried) ** 2).sum() - weight * ((p - anchor) ** 2).sum()

    constants = [difference(rng.normal(size=(7, 3))) for _ in range(4)]
    assert np.ptp(constants) < 1e-9 * abs(constants[0])
    assert temporal_anchor(initial, carried, beta, 0.0) == (initial, beta)


def test_the_previous_result_is_carried_by_the_bases_difference():
    rng = np.random.default_rng(1)
    points, base_before, base_now = rng.normal(size=(3, 6, 3))
    carried = PreviousFrame(points, base_before).carried(base_now)
    assert np.allclose(carried - points, base_now - base_before)


def test_the_body_moving_near_the_hair_counts_and_far_from_it_does_not():
    hair = np.array([[0.0, 1.6, 0.0], [0.0, 1.5, 0.1]])
    body = np.array([[0.0, 1.55, 0.02], [0.0, 0.5, 0.0], [0.3, 0.2, 0.0]])
    moved = body + np.array([[0.01, 0.0, 0.0], [0.2, 0.0, 0.0], [0.0, 0.3, 0.0]])
    assert body_motion_near_hair(hair, body, moved) == pytest.approx(0.01)
    assert body_motion_near_hair(hair + 5.0, body, moved) == 0.0
    coherence = frame_coherence(hair, hair + [0.0, 0.025, 0.0], body, moved)
    assert coherence["largest_jump_m"] == pytest.approx(0.025) and coherence["pops"]
    assert coherence["particles_beyond"] == 2  # 25 mm against a bound of 21 mm


def test_frames_of_another_mesh_are_refused():
    one = toy.toy_character(name="one")
    cut = Character(one.vertices, one.faces[:-10], name="cut")
    with pytest.raises(InputError) as caught:
        require_one_topology([one, one, cut])
    assert caught.value.code == "sequence_topology" and "frame 2" in caught.value.problem
    with pytest.raises(InputError) as caught:
        require_one_topology([])
    assert caught.value.code == "bad_frames"


@pytest.mark.parametrize("warm, temporal", [(True, 2e9), (True, -0.1), (False, 1e4), (True, float("nan"))])
def test_absurd_sequence_options_are_refused(warm, temporal):
    with pytest.raises(InputError) as caught:
        SequenceOptions(warm=warm, temporal=temporal).validate()
    assert caught.value.code == "bad_option" and "temporal" in caught.value.problem


def test_a_temporal_term_for_a_baseline_is_refused():
    one = toy.toy_character(name="one")
    adaptable = solver.preprocess(one, generate_groom(one, "short", 10, 6, seed=0))
    with pytest.raises(InputError) as caught:
        next(sequence.retarget_sequence(adaptable, [one, one], solver.RetargetOptions(method="root-translate"),
                                        SequenceOptions(temporal=1e4)))
    assert caught.value.code == "bad_option" and "root-translate" in caught.value.problem


def test_a_warm_frames_grid_near_its_start_changes_nothing_of_the_result(sweep, monkeypatch):
    """Warm frames query their distance grid's nodes only near the carried start (pipeline.WARM_GRID_REACH): the
    other nodes' bounds only send more particles to the exact query, so the frames are the full grid's."""
    from hairport.solver import pipeline

    assert math.isfinite(pipeline.WARM_GRID_REACH)
    monkeypatch.setattr(pipeline, "WARM_GRID_REACH", math.inf)
    full = list(sequence.retarget_sequence(sweep["adaptable"], sweep["frames"]))
    for restricted, everywhere in zip(sweep["warm"], full):
        assert np.abs(restricted.hair.points - everywhere.hair.points).max() < 1e-9


def test_frames_of_another_topology_are_wrapped_once_and_carry_the_wrap(sweep):
    """The toy sweep remeshed (one mesh for every frame, not the source's): frame 0 is wrapped, the later frames
    carry its wrap on their surface (no wrap of their own), with nothing inside. Each lands where a cold retarget
    onto the sweep's own frame (the source's mesh: no wrap, the exact correspondence) does, within 0.5 mm (a wrap
    of each frame on its own slides along the growing body: 2-4 mm off by frame 2)."""
    from hairport.solver.mesh.query import MeshQuery
    from hairport.solver.mesh.triangles import barycentric_coordinates, interpolate_barycentric
    from hairport.solver.synthetic.remesh import remeshed_character
    from hairport.solver.wrapping import EmbeddedWrap

    frames, adaptable = sweep["frames"], sweep["adaptable"]
    remeshed = remeshed_character(frames[0], 3000, seed=1)
    on_first = MeshQuery(frames[0].vertices, frames[0].faces).signed_distance(remeshed.vertices)
    weights = barycentric_coordinates(on_first.closest, frames[0].vertices[frames[0].faces[on_first.faces]])
    bodies = [Character(interpolate_barycentric(frame.vertices, frame.faces, on_first.faces, weights), remeshed.faces,
                        name=f"remeshed {number}") for number, frame in enumerate(frames[:3])]
    results = list(sequence.retarget_sequence(adaptable, bodies))
    assert "wrap" in results[0].timings and not results[0].wrapped.report.get("carried")
    held = EmbeddedWrap.of(results[0].wrapped, bodies[0])
    np.testing.assert_allclose(held.on(bodies[0]).shape.vertices, results[0].wrapped.shape.vertices, rtol=0, atol=1e-12)
    for number, result in enumerate(results[1:], start=1):
        assert "wrap" not in result.timings and result.wrapped.report["carried"] is True
        assert result.metrics["penetrating_particles"] == 0 and result.metrics["crossing_segments"]["count"] == 0
        mean = np.linalg.norm(result.hair.points - sweep["cold"][number].hair.points, axis=1).mean()
        assert mean < 5e-4, (number, mean)
    assert results[1].wrapped.key != results[2].wrapped.key != results[0].wrapped.key
