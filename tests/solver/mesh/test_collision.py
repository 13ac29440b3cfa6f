"""The surface hair collides with (solver/mesh/collision.py): closed, open, nested and inverted bodies."""

import threading

import igl
import numpy as np
import pytest

from hairport.solver.mesh.collision import body_key, collision_faces, collision_query, forget_bodies
from hairport.solver.mesh.inside import WindingNumber
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.errors import InputError
from tests.solver.mesh.meshes import icosphere
from tests.solver.mesh.test_inside import face_probes, open_capsule


def test_a_closed_shell_is_its_own_collision_surface_with_pseudonormal_signs():
    vertices, faces = icosphere()
    body = collision_query(vertices, faces)
    assert body.closed and body.inside_test.manifold is None
    np.testing.assert_array_equal(body.faces, faces)
    rng = np.random.default_rng(0)
    points = rng.uniform(-0.12, 0.12, size=(2000, 3))
    np.testing.assert_array_equal(body.signed_distance(points).distance,
                                  MeshQuery(vertices, faces).signed_distance(points).distance)
    np.testing.assert_array_equal(body.inside(points), WindingNumber(vertices, faces).inside(points))


def test_an_open_bust_is_inside_above_its_cut_and_outside_below_it():
    """The plain query's pseudonormal puts a point 3 cm under the cut inside (its closest point
    is on the rim, seen from within the wall); the collision surface does not."""
    vertices, faces = open_capsule()
    body = collision_query(vertices, faces, "bust")
    assert not body.closed and body.inside_test.manifold is not None
    points = np.array([[0.0, 0.0, 0.03], [0.0, 0.0, 0.06], [0.09, 0.0, -0.005], [0.0, 0.0, -0.03]])
    sd = body.signed_distance(points)
    np.testing.assert_array_equal(sd.distance < 0, [True, True, False, False])
    np.testing.assert_array_equal(body.inside(points), [True, True, False, False])
    plain = MeshQuery(vertices, faces).signed_distance(points).distance
    assert plain[2] < 0 and plain[3] < 0  # the side of the nearest feature, not inside
    # |distance| is the distance to the surface either way; the normal points out for the inside ones
    np.testing.assert_allclose(np.abs(sd.distance), np.abs(plain), rtol=0, atol=1e-15)
    np.testing.assert_allclose(np.einsum("ij,ij->i", sd.normal[:2], sd.closest[:2] - points[:2]),
                               -sd.distance[:2], rtol=1e-12)


def test_next_to_the_skin_of_an_open_bust_the_sign_is_exact():
    """1 nm off a face, where the single-precision winding number is noise, the pseudonormal decides."""
    vertices, faces = open_capsule()
    body = collision_query(vertices, faces)
    for offset in (1e-9, 1e-6, 1e-3):
        assert (body.signed_distance(face_probes(vertices, faces, -offset)).distance < 0).all()
        assert (body.signed_distance(face_probes(vertices, faces, offset)).distance > 0).all()


def test_an_inner_shell_is_no_collision_surface():
    """A particle between the skin and an inner shell is inside, and its way out is the skin,
    not across the inner shell (where the plain query's pseudonormal sends it)."""
    outer, outer_faces = icosphere(radius=0.1)
    inner, inner_faces = icosphere(radius=0.05)
    vertices = np.vstack([outer, inner])
    faces = np.vstack([outer_faces, inner_faces + len(outer)])
    body = collision_query(vertices, faces)
    assert body.closed and len(body.faces) == len(outer_faces)
    point = np.array([[0.0, 0.0, 0.06]])  # 1 cm over the inner shell, 4 cm under the skin
    sd = body.signed_distance(point)
    assert -0.041 < sd.distance[0] < -0.039 and sd.closest[0, 2] > 0.09
    plain = MeshQuery(vertices, faces).signed_distance(point)
    assert 0.009 < plain.distance[0] < 0.011  # "outside", 1 cm from the inner shell
    assert body.inside(np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.12]])).tolist() == [True, False]


def test_a_body_turned_inside_out_is_refused():
    vertices, faces = icosphere()
    with pytest.raises(InputError, match="encloses no volume") as error:
        collision_query(vertices, faces[:, ::-1], "inverted")
    assert error.value.code == "no_inside" and error.value.source == "inverted"


def test_the_makehuman_body_leaves_out_only_the_faces_where_its_lips_cross():
    """MakeHuman bodies cross themselves in a few faces: the heavy male at the lips (the female
    and the child at the toes): those separate nothing and leave the collision surface."""
    from hairport.solver.synthetic.makehuman import PRESETS, build_character
    from tests.solver.synthetic.makehuman_fixtures import makehuman_assets

    makehuman_assets()
    male = build_character(PRESETS["heavy-male"])
    body = collision_query(male.vertices, male.faces, male.name)
    kept = set(map(tuple, body.faces))
    left_out = np.array([f for f in male.faces if tuple(f) not in kept])
    assert 0 < len(left_out) < 30 and body.closed
    centres = male.vertices[left_out].mean(axis=1)
    mouth = male.vertices[male.vertices[:, 1] > male.vertices[:, 1].max() - 0.25]
    mouth = mouth[np.argmax(mouth[:, 2])]  # the tip of the nose, just over the mouth
    assert np.linalg.norm(centres - mouth, axis=1).max() < 0.06 and np.abs(centres[:, 0]).max() < 0.03
    # around the head and shoulders, 3 and 6 cm deep included: the sign is the exact winding number's
    head = male.vertices[male.vertices[:, 1] > male.vertices[:, 1].max() - 0.4]
    points = np.random.default_rng(1).uniform(head.min(axis=0) - 0.03, head.max(axis=0) + 0.03, size=(20000, 3))
    exact = igl.winding_number(male.vertices, male.faces, points) > 0.5
    assert 2000 < exact.sum() < 18000
    np.testing.assert_array_equal(body.signed_distance(points).distance < 0, exact)


def test_a_body_is_analysed_once_per_thread():
    vertices, faces = icosphere()
    first = collision_query(vertices, faces)
    assert collision_query(vertices.copy(), faces.copy()) is first
    assert collision_query(vertices + [0.0, 0.0, 1e-9], faces) is not first
    other = []
    thread = threading.Thread(target=lambda: other.append(collision_query(vertices, faces)))
    thread.start()
    thread.join()
    assert other[0] is not first and np.array_equal(other[0].faces, first.faces)
    forget_bodies()  # this thread's kept queries dropped: the body is analysed again, to the same surface
    again = collision_query(vertices, faces)
    assert again is not first and np.array_equal(again.faces, first.faces)
    assert collision_query(vertices, faces) is again


def test_a_kept_collision_surface_gives_the_same_query():
    """The faces kept from an earlier build (another process's, the per-target cache) give the same surface and
    signs without the winding numbers over every face; a mask of another body is refused."""
    outer, outer_faces = icosphere(radius=0.1)
    inner, inner_faces = icosphere(radius=0.05)
    vertices = np.vstack([outer, inner])
    faces = np.vstack([outer_faces, inner_faces + len(outer)])
    separating = collision_faces(vertices, faces)
    assert separating.dtype == bool and separating.sum() == len(outer_faces) and not separating[len(outer_faces):].any()
    built = collision_query(vertices, faces)
    threaded = []  # another thread: an empty in-memory cache, so the kept mask is what it uses
    thread = threading.Thread(target=lambda: threaded.append(collision_query(vertices, faces, separating=separating)))
    thread.start()
    thread.join()
    kept = threaded[0]
    assert kept is not built and np.array_equal(kept.faces, built.faces) and kept.closed == built.closed
    points = np.random.default_rng(0).uniform(-0.12, 0.12, size=(500, 3))
    np.testing.assert_array_equal(kept.signed_distance(points).distance, built.signed_distance(points).distance)
    assert body_key(vertices, faces) == body_key(vertices.copy(), faces.astype(np.int32))
    assert len(body_key(vertices, faces)) == 32 and body_key(vertices + 1e-9, faces) != body_key(vertices, faces)
    with pytest.raises(ValueError, match="shape"):
        collision_query(vertices + 1.0, faces, separating=separating[:-1])
    with pytest.raises(InputError) as error:
        collision_faces(outer, outer_faces[:, ::-1], "inverted")
    assert error.value.code == "no_inside"


def test_a_moved_frame_keeps_the_surface_it_can_and_answers_as_a_new_build():
    """A frame of a sequence (the same mesh, its vertices moved) moves the previous frame's collision query: the
    same distances, signs and surface as a query built on the frame alone, with the face search refit (its nodes
    shared); where the motion changes which faces separate, the query is built anew."""
    outer, outer_faces = icosphere(radius=0.1)
    faces = np.vstack([outer_faces, outer_faces + len(outer)])
    apart = np.vstack([outer, outer + [0.3, 0.0, 0.0]])
    closer = np.vstack([outer, outer + [0.25, 0.0, 0.0]])  # still apart: every face separates
    overlapping = np.vstack([outer, outer + [0.1, 0.0, 0.0]])  # a quarter of each sphere inside the other
    points = np.random.default_rng(3).uniform(-0.15, 0.4, size=(3000, 3))
    first = collision_query(apart, faces)
    first.signed_distance(points[:1])  # its face search built
    moved = collision_query(closer, faces, moved_from=first)
    fresh = _in_another_thread(lambda: collision_query(closer, faces))
    np.testing.assert_array_equal(moved.faces, fresh.faces)
    np.testing.assert_allclose(moved.signed_distance(points).distance, fresh.signed_distance(points).distance,
                               rtol=0, atol=1e-15)
    assert moved._closest._tree.child is first._closest._tree.child  # refit, not built
    np.testing.assert_array_equal(moved.inside(points), WindingNumber(closer, faces).inside(points))
    assert moved.inside_test.winding.vertices is not first.inside_test.winding.vertices
    changed = collision_query(overlapping, faces, moved_from=moved)
    assert len(changed.faces) < len(faces) and changed.inside_test.manifold is not None
    np.testing.assert_array_equal(changed.inside(points), WindingNumber(overlapping, faces).inside(points))
    with pytest.raises(ValueError, match="moved"):
        first.moved(closer[:-1], first.inside_test)
    with pytest.raises(ValueError, match="inside test"):
        first.moved(closer)
    with pytest.raises(ValueError, match="inside test"):
        MeshQuery(apart, faces).moved(closer, first.inside_test)


def _in_another_thread(build):
    """What ``build()`` returns in a thread of its own (an empty per-thread cache of bodies)."""
    out = []
    thread = threading.Thread(target=lambda: out.append(build()))
    thread.start()
    thread.join()
    return out[0]
