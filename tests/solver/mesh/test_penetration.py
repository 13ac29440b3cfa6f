"""The final penetration check (solver/mesh/penetration.py): push out what a method left inside, or refuse."""

import numpy as np
import pytest
import trimesh

from hairport.solver.mesh import penetration
from hairport.solver.mesh.clearance import INSIDE_PUSH_ROUNDS, push_inside_out
from hairport.solver.mesh.collision import collision_query
from hairport.solver.mesh.penetration import inside_depths, resolve_crossings, resolve_penetration
from hairport.solver.mesh.segment_crossing import crossing_segments, weld_runs
from hairport.solver.model.errors import InputError, PenetrationRemaining
from tests.solver.mesh.meshes import icosphere
from tests.solver.mesh.test_inside import open_capsule

EPS_C = 5e-4


def boxes(*bounds):
    """Closed boxes ``(lower, upper)`` (m) as one mesh."""
    vertices, faces, n = [], [], 0
    for lower, upper in bounds:
        box = trimesh.creation.box(bounds=[lower, upper])
        vertices.append(np.asarray(box.vertices))
        faces.append(np.asarray(box.faces, dtype=np.int64) + n)
        n += len(box.vertices)
    return np.vstack(vertices), np.vstack(faces)


@pytest.mark.parametrize("shape", ["sphere", "open bust"])
def test_particles_3_and_6_cm_deep_are_pushed_out_and_reported(shape):
    vertices, faces = icosphere() if shape == "sphere" else open_capsule()
    body = collision_query(vertices, faces)
    centre = np.array([0.0, 0.0, 0.0 if shape == "sphere" else 0.1])  # the bust's wall is 10 cm off its cut
    direction = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-0.6, 0.8, 0.0], [0.6, -0.8, 0.0]])
    radius = np.linalg.norm(body.signed_distance(centre + 0.2 * direction).closest - centre, axis=1)
    depth = np.array([0.03, 0.06, 0.03, 0.06])
    points = centre + np.vstack([(radius - depth)[:, None] * direction, 0.2 * direction])  # 4 inside, 4 outside
    is_root = np.zeros(8, dtype=bool)
    is_root[4] = True
    rows, found = inside_depths(points, is_root, body)
    np.testing.assert_array_equal(rows, [0, 1, 2, 3])
    np.testing.assert_allclose(found, depth, atol=2e-3)  # facets: the distance to them is not along the ray
    out, resolved = resolve_penetration(points, is_root, body, EPS_C)
    assert resolved["particles"] == 4 and resolved["deepest_m"] == pytest.approx(found.max(), abs=1e-15)
    after = body.signed_distance(out).distance
    np.testing.assert_allclose(after[:4], EPS_C, rtol=0, atol=1e-12)  # straight out through the closest point
    np.testing.assert_array_equal(out[4:], points[4:])
    assert inside_depths(out, is_root, body)[0].size == 0


def test_nothing_inside_returns_the_same_array():
    vertices, faces = icosphere()
    points = np.array([[0.2, 0.0, 0.0], [0.0, 0.0, 0.0]])
    is_root = np.array([False, True])  # a root at the centre is not checked
    same, resolved = resolve_penetration(points, is_root, collision_query(vertices, faces), EPS_C)
    assert same is points and resolved == {"particles": 0, "deepest_m": 0.0}


def test_a_particle_between_an_inner_shell_and_the_skin_leaves_through_the_skin():
    outer, outer_faces = icosphere(radius=0.1)
    inner, inner_faces = icosphere(radius=0.05)
    body = collision_query(np.vstack([outer, inner]), np.vstack([outer_faces, inner_faces + len(outer)]))
    points = np.array([[0.0, 0.0, 0.06], [0.0, 0.03, 0.0]])  # 1 cm over the inner shell; inside it
    out, resolved = resolve_penetration(points, np.zeros(2, dtype=bool), body, EPS_C)
    assert resolved["particles"] == 2
    np.testing.assert_allclose(body.signed_distance(out).distance, EPS_C, rtol=0, atol=1e-12)
    assert np.linalg.norm(out, axis=1).min() > 0.098


def test_a_gap_narrower_than_the_clearance_takes_a_smaller_push():
    """Two blocks 0.2 mm apart: 0.5 mm out of one is inside the other; a quarter of it lands in the gap."""
    vertices, faces = boxes(([0.0, 0.0, 0.0], [0.02, 0.02, 0.02]), ([0.0202, 0.0, 0.0], [0.04, 0.02, 0.02]))
    body = collision_query(vertices, faces)
    points = np.array([[0.018, 0.01, 0.01]])  # 2 mm inside the first block, nearest its face on the gap
    out, resolved = resolve_penetration(points, np.zeros(1, dtype=bool), body, EPS_C)
    assert resolved["particles"] == 1
    assert 0.02 < out[0, 0] < 0.0202 and body.signed_distance(out).distance[0] > 0


def test_a_crack_narrower_than_every_push_fails_with_its_code():
    """Two blocks 10 um apart: every round (down to eps_c / 32 = 15.6 um) crosses the crack into
    the other block; the result is refused, not reported."""
    vertices, faces = boxes(([0.0, 0.0, 0.0], [0.02, 0.02, 0.02]), ([0.02001, 0.0, 0.0], [0.04, 0.02, 0.02]))
    body = collision_query(vertices, faces, "blocks")
    points = np.array([[0.018, 0.01, 0.01], [0.01, 0.01, 0.01], [0.05, 0.01, 0.01]])
    assert EPS_C / 2 ** (INSIDE_PUSH_ROUNDS - 1) > 1e-5
    with pytest.raises(PenetrationRemaining, match=r"^blocks: 1 of the 2 hair particles .*deepest 10.00 mm.*"
                                                   r"particle 0\); no penetration-free result") as error:
        resolve_penetration(points, np.zeros(3, dtype=bool), body, EPS_C, "blocks")
    assert error.value.code == "penetration_remaining" and isinstance(error.value, InputError)


def strand_crossings(points, offsets, query):
    hair_segments = np.array([[i, i + 1] for s in range(len(offsets) - 1) for i in range(offsets[s], offsets[s + 1] - 1)])
    return hair_segments, crossing_segments(points, hair_segments, np.isin(np.arange(len(points)), offsets[:-1]), query)


def test_a_segment_sagging_into_a_shoulder_has_its_ends_lifted_by_its_depth_plus_the_clearance():
    sphere = collision_query(*icosphere(radius=0.05, subdivisions=5), "shoulder")
    top = sphere.signed_distance(np.array([[0.0, 0.0, 0.1]])).closest[0]
    ends = []
    for side in (-0.008, 0.008):  # a 16 mm chord 0.5 mm off a 5 cm radius sags 0.14 mm into it
        sd = sphere.signed_distance((top + [side, 0.0, 0.0])[None])
        ends.append(sd.closest[0] + EPS_C * sd.normal[0])
    points = np.vstack([[0.0, 0.0, 0.2], *ends])  # a root far above, then the chord
    offsets = np.array([0, 3])
    segments, before = strand_crossings(points, offsets, sphere)
    assert before.rows.tolist() == [1]
    is_root = np.array([True, False, False])
    out, resolved, after, _ = resolve_crossings(points, segments, is_root, sphere, EPS_C, offsets, "shoulder")
    assert resolved == {"segments": 1, "deepest_m": pytest.approx(before.depth[0]), "tails_moved": 0}
    assert after.count == 0
    lift = np.linalg.norm(out - points, axis=1)
    assert lift[0] == 0.0 and lift[1:] == pytest.approx(before.depth[0] + EPS_C, rel=0.05)


def test_a_strand_through_a_thin_plate_has_its_tail_taken_back_across_it():
    """A 3 mm plate between two particles 1 cm off it on either side: lifting the ends along a normal
    cannot clear the segment; the tail (the far end and what follows) comes back across, its shape kept,
    where it then passes the plate's edge."""
    plate = collision_query(*boxes(([-0.05, -0.05, -0.0015], [0.05, 0.05, 0.0015])), "plate")
    offsets = np.array([0, 4])
    is_root = np.array([True, False, False, False])
    past_the_edge = np.array([[0.04, 0.0, 0.05], [0.045, 0.0, 0.0115], [0.049, 0.0, -0.0115], [0.09, 0.0, -0.008]])
    segments, before = strand_crossings(past_the_edge, offsets, plate)
    assert before.rows.tolist() == [1]
    out, resolved, after, _ = resolve_crossings(past_the_edge, segments, is_root, plate, EPS_C, offsets, "plate")
    assert resolved["segments"] == 1 and resolved["tails_moved"] == 1 and after.count == 0
    assert (plate.signed_distance(out[1:]).distance > 0).all() and (out[1:3, 2] > 0).all()  # on the root's side
    # the tail keeps its shape (but for the pushes after it, tens of micrometres)
    np.testing.assert_allclose(out[3] - out[2], past_the_edge[3] - past_the_edge[2], atol=1e-4)

    # a tail that goes on straight through: pulled back segment after segment, it ends folded on the near side
    straight_through = np.array([[0.0, 0.0, 0.05], [0.0, 0.0, 0.0115], [0.004, 0.0, -0.0115], [0.008, 0.0, -0.04]])
    out, resolved, after, _ = resolve_crossings(straight_through, segments, is_root, plate, EPS_C, offsets, "plate")
    assert after.count == 0 and resolved["segments"] == 1
    assert (out[1:, 2] > 0.0015).all() and (plate.signed_distance(out[1:]).distance > 0).all()


def test_the_check_returns_the_distances_at_its_result_querying_only_what_moved(monkeypatch):
    """The rounds query again only the particles they moved; the distances handed back are a fresh query's."""
    plate = collision_query(*boxes(([-0.05, -0.05, -0.0015], [0.05, 0.05, 0.0015])), "plate")
    offsets = np.array([0, 5])
    is_root = np.array([True, False, False, False, False])
    # a particle far above that no round moves, then a tail through the plate
    points = np.array([[0.04, 0.0, 0.05], [0.04, 0.0, 0.08], [0.045, 0.0, 0.0115], [0.049, 0.0, -0.0115],
                       [0.09, 0.0, -0.008]])
    segments, _ = strand_crossings(points, offsets, plate)
    asked = []
    signed_distance = plate.signed_distance
    monkeypatch.setattr(plate, "signed_distance", lambda p: asked.append(np.array(p)) or signed_distance(p))
    out, resolved, after, distance = resolve_crossings(points, segments, is_root, plate, EPS_C, offsets, "plate")
    assert resolved["segments"] == 1 and after.count == 0
    np.testing.assert_array_equal(out[:2], points[:2])  # the root and the particle above stay
    assert distance[0] == 0.0
    np.testing.assert_array_equal(distance[1:], signed_distance(out[1:]).distance)
    # one query of every free particle, then of the moved ones only: the particle above is asked about once
    assert len(asked[0]) == 4 and sum(int((query == points[1]).all(axis=1).sum()) for query in asked) == 1


def test_a_segment_the_rounds_do_not_clear_refuses_the_result(monkeypatch):
    plate = collision_query(*boxes(([-0.05, -0.05, -0.0015], [0.05, 0.05, 0.0015])), "plate")
    points = np.array([[0.0, 0.0, 0.05], [0.0, 0.0, 0.0115], [0.004, 0.0, -0.0115], [0.008, 0.0, -0.04]])
    offsets = np.array([0, 4])
    segments, _ = strand_crossings(points, offsets, plate)
    monkeypatch.setattr(penetration, "SEGMENT_PUSH_ROUNDS", 0)  # no round to move it
    with pytest.raises(PenetrationRemaining) as error:
        resolve_crossings(points, segments, np.array([True, False, False, False]), plate, EPS_C, offsets, "plate")
    assert error.value.code == "penetration_remaining"
    assert error.value.problem.startswith("segments of hair still pass through the target body between two particles "
                                          "outside it: 1, after moving the 1 the method left there")
    assert "(the deepest left: strand 0, segment 1; 0 particles inside)" in error.value.problem


def test_welded_particles_at_a_crossing_segments_end_move_together():
    sphere = collision_query(*icosphere(radius=0.05, subdivisions=4), "ball")
    top = sphere.signed_distance(np.array([[0.0, 0.0, 0.1]])).closest[0]
    a = sphere.signed_distance((top + [-0.009, 0.0, 0.0])[None])
    b = sphere.signed_distance((top + [0.009, 0.0, 0.0])[None])
    chord = np.vstack([a.closest + EPS_C * a.normal, b.closest + EPS_C * b.normal])
    points = np.vstack([[0.0, 0.0, 0.2], chord[0], chord[1], chord[1]])  # the chord's end repeated
    segments = np.array([[0, 1], [1, 2], [2, 3]])
    welded = np.array([False, False, True, False])
    out, _, after, _ = resolve_crossings(points, segments, np.array([True, False, False, False]), sphere, EPS_C,
                                      np.array([0, 4]), "ball", welded=welded)
    assert after.count == 0 and np.linalg.norm(out[2] - points[2]) > 1e-4
    np.testing.assert_array_equal(out[3], out[2])


def test_a_weld_run_pushed_out_of_a_corner_moves_as_one():
    """Two welded particles a rounding apart inside a box, by its edge: pushed independently each takes its own
    nearest face and the weld opens by more than the clearance; as a run they move by one push."""
    box = collision_query(*boxes(([-0.05, -0.05, -0.05], [0.05, 0.05, 0.05])), "box")
    points = np.array([[0.0, 0.0, 0.2], [0.049, 0.049 + 1e-11, 0.0], [0.049 + 1e-11, 0.049, 0.0]])
    apart, _ = push_inside_out(points, np.array([1, 2]), box, EPS_C)
    assert np.linalg.norm(apart[1] - apart[2]) > EPS_C
    runs = weld_runs(np.array([False, True, False]))
    together, left = push_inside_out(points, np.array([1, 2]), box, EPS_C, runs)
    assert len(left) == 0 and (box.signed_distance(together[1:]).distance > 0).all()
    assert np.linalg.norm(together[1] - together[2]) < 1e-10
    np.testing.assert_array_equal(together[0], points[0])
