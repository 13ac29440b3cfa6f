"""Tests of the naive retargeting baselines (solver/baselines.py) on a synthetic ellipsoid head."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.spatial.transform import Rotation

from hairport.solver.baselines import BASELINE_METHODS, parse_method, retarget_baseline
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.character import Character, Skeleton
from hairport.solver.model.errors import InputError, TopologyMismatch
from hairport.solver.model.hair import Hair
from hairport.solver.transfer.anchors import root_targets, surface_anchors
from tests.solver.hair_shapes import HEAD_RADIUS, ellipsoid_head, hanging_groom

SNAPPING_METHODS = ("root-translate", "root-rigid", "affine-translate", "rbf-warp")


@pytest.fixture(scope="module")
def head() -> Character:
    return ellipsoid_head()


@pytest.fixture(scope="module")
def hair(head: Character) -> Hair:
    hair = hanging_groom(head)
    assert hair.n_strands > 80
    return hair


def _deformed(head: Character) -> Character:
    """A smooth non-rigid target of the same topology."""
    v = head.vertices
    w = v * np.array([1.15, 0.95, 1.05]) + 0.02 * np.sin(v[:, [1, 2, 0]] / HEAD_RADIUS * 2.0)
    return head.with_vertices(w + np.array([0.01, -0.02, 0.3]), name="deformed")


def anchor_roots(source_query: MeshQuery, hair: Hair) -> tuple[np.ndarray, np.ndarray]:
    """The baselines' root anchors: each root's closest point on the source as face and barycentrics."""
    return surface_anchors(source_query, source_query.signed_distance(hair.points[hair.roots]))


# --------------------------------------------------------------------------------------------


def test_parse_method():
    assert parse_method("rbf-warp") == ("rbf-warp", False)
    assert parse_method("root-rigid+pushout") == ("root-rigid", True)
    assert parse_method(" Root-Translate+PUSHOUT ") == ("root-translate", True)


@pytest.mark.parametrize("name", ["bogus", "rbf", "+pushout", "root-rigid+pushout+pushout"])
def test_unknown_method(head, hair, name):
    with pytest.raises(InputError) as info:
        retarget_baseline(name, head, head, hair)
    message = str(info.value)
    assert "unknown baseline method" in message and repr(name) in message
    for valid in BASELINE_METHODS:
        assert valid in message
    assert info.value.code == "unknown_method"


def test_bad_clearance_and_topology(head, hair):
    with pytest.raises(InputError, match="clearance"):
        retarget_baseline("root-translate", head, head, hair, clearance=-1.0)
    other = Character(head.vertices[:-1], head.faces[:10], name="other")
    with pytest.raises(TopologyMismatch):
        retarget_baseline("root-translate", head, other, hair)


@pytest.mark.parametrize("method", BASELINE_METHODS)
def test_identity(head, hair, method):
    out = retarget_baseline(method, head, head, hair)
    np.testing.assert_allclose(out.points, hair.points, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(out.offsets, hair.offsets)
    np.testing.assert_array_equal(out.thickness, hair.thickness)
    # the groom clears the head by >= 1 mm, so push-out (0.5 mm) changes nothing
    pushed = retarget_baseline(method + "+pushout", head, head, hair)
    np.testing.assert_allclose(pushed.points, hair.points, rtol=0, atol=1e-12)


@pytest.mark.parametrize("method", BASELINE_METHODS)
def test_translation(head, hair, method):
    shift = np.array([0.12, -0.3, 0.05])
    target = head.with_vertices(head.vertices + shift)
    out = retarget_baseline(method, head, target, hair)
    np.testing.assert_allclose(out.points, hair.points + shift, rtol=0, atol=1e-9)


# tolerance (m) of the rigid-motion test; all three are exact in theory (rbf-warp: a thin-plate spline
# with a linear term reproduces affine fields; measured 6e-15, but it solves a dense system)
RIGID_TOLERANCE = {"root-rigid": 1e-9, "affine-translate": 1e-9, "rbf-warp": 1e-9}


@pytest.mark.parametrize("method", sorted(RIGID_TOLERANCE))
def test_rigid_motion(head, hair, method):
    rotation = Rotation.from_euler("xyz", [20, -35, 50], degrees=True).as_matrix()
    shift = np.array([0.3, 0.1, -0.2])
    target = head.with_vertices(head.vertices @ rotation.T + shift)
    out = retarget_baseline(method, head, target, hair)
    expected = hair.points @ rotation.T + shift
    np.testing.assert_allclose(out.points, expected, rtol=0, atol=RIGID_TOLERANCE[method])


@pytest.mark.parametrize("method", SNAPPING_METHODS)
def test_roots_land_on_targets(head, hair, method):
    target = _deformed(head)
    faces, bary = anchor_roots(MeshQuery(head.vertices, head.faces), hair)
    expected_roots = root_targets(target, faces, bary)
    out = retarget_baseline(method, head, target, hair)
    np.testing.assert_allclose(out.points[out.roots], expected_roots, rtol=0, atol=1e-12)
    assert np.isfinite(out.points).all()


def test_root_translate_keeps_strand_shapes(head, hair):
    out = retarget_baseline("root-translate", head, _deformed(head), hair)
    rel_in = hair.points - hair.points[hair.roots][hair.strand_of]
    rel_out = out.points - out.points[out.roots][out.strand_of]
    np.testing.assert_allclose(rel_out, rel_in, rtol=0, atol=1e-12)


def test_global_translate_moves_by_mean_root_displacement(head, hair):
    target = _deformed(head)
    faces, bary = anchor_roots(MeshQuery(head.vertices, head.faces), hair)
    shift = (root_targets(target, faces, bary) - hair.points[hair.roots]).mean(axis=0)
    out = retarget_baseline("global-translate", head, target, hair)
    np.testing.assert_allclose(out.points, hair.points + shift, rtol=0, atol=1e-12)


def test_affine_uses_head_bone_region(head, hair):
    """With a `head` bone, only its vertices drive the affine fit: the rest may do anything."""
    upper = head.vertices[:, 2] > 0
    weights = sp.csr_matrix(np.stack([upper, ~upper], axis=1).astype(float))
    skeleton = Skeleton(["head", "neck"], [1, -1], [[0, 0, 0], [0, 0, -0.1]], [[0, 0, 0.1], [0, 0, 0]])
    rigged = Character(head.vertices, head.faces, skeleton, weights, name="rigged")
    scale, shift = 1.2, np.array([0.0, 0.05, 0.1])
    moved = np.where(upper[:, None], head.vertices * scale + shift, head.vertices * [2.0, 0.5, 1.0])
    target = rigged.with_vertices(moved)
    out = retarget_baseline("affine-translate", rigged, target, hair)
    np.testing.assert_allclose(out.points, hair.points * scale + shift, rtol=0, atol=1e-12)


def _grown_sideways(head: Character) -> Character:
    """The head widened by 40 % sideways: hair hanging down the sides ends up inside."""
    return head.with_vertices(head.vertices * np.array([1.4, 1.4, 1.0]), name="wide")


@pytest.mark.parametrize("method", BASELINE_METHODS)
def test_push_out_removes_penetrations(head, hair, method):
    target = _grown_sideways(head)
    query = MeshQuery(target.vertices, target.faces)
    clearance = 5e-4
    plain = retarget_baseline(method, head, target, hair)
    pushed = retarget_baseline(method, head, target, hair, pushout=True, clearance=clearance, target_query=query)
    non_root = ~hair.is_root
    d_plain = query.signed_distance(plain.points).distance
    d_pushed = query.signed_distance(pushed.points).distance
    if method in ("global-translate", "root-translate", "root-rigid"):
        assert (d_plain[non_root] < 0).sum() > 10  # the case does penetrate
    assert d_pushed[non_root].min() >= clearance - 1e-9
    # roots untouched, and particles already clear of the body untouched
    np.testing.assert_array_equal(pushed.points[pushed.roots], plain.points[plain.roots])
    clear = non_root & (d_plain >= clearance)
    np.testing.assert_array_equal(pushed.points[clear], plain.points[clear])
    # the suffix is the same switch
    suffixed = retarget_baseline(method + "+pushout", head, target, hair, clearance=clearance, target_query=query)
    np.testing.assert_array_equal(suffixed.points, pushed.points)


def test_empty_hair(head):
    empty = Hair(np.zeros((0, 3)), np.zeros(1, dtype=np.int64))
    for method in BASELINE_METHODS:
        assert retarget_baseline(method + "+pushout", head, _deformed(head), empty).n_particles == 0
