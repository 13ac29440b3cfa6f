"""Tests for solver/synthetic/toy.py: the toy upper body, one topology for every parameter choice."""

from __future__ import annotations

import igl
import numpy as np
import pytest
import trimesh

from hairport.solver.synthetic.toy import TOY_BONES, TOY_RING_VERTICES, TOY_RINGS, toy_character
from tests.solver.synthetic.toy_fixtures import PRESET_B


def test_toy_topology_identical_across_parameters(toy_a, toy_b):
    others = [toy_b, toy_character(head_scale=(0.8, 1.2, 0.9), neck_radius=0.04, chest_depth=0.3, nose=False)]
    for other in others:
        assert other.n_vertices == toy_a.n_vertices
        assert np.array_equal(other.faces, toy_a.faces)
        assert not np.allclose(other.vertices, toy_a.vertices)
    assert 2000 <= toy_a.n_faces <= 20000


@pytest.mark.parametrize("preset", [{}, PRESET_B])
def test_toy_is_watertight_and_outward(preset):
    c = toy_character(**preset)
    mesh = trimesh.Trimesh(c.vertices, c.faces, process=False)
    assert mesh.is_watertight
    assert mesh.is_winding_consistent
    assert mesh.volume > 0.01  # m^3: head + neck + torso
    assert np.all(mesh.area_faces > 0)
    lo, hi = c.vertices.min(0), c.vertices.max(0)
    assert hi[1] - lo[1] == pytest.approx(0.6, abs=0.1)  # Y up, meters


@pytest.mark.parametrize("preset", [{}, PRESET_B])
def test_toy_skeleton_inside_and_weights(preset):
    c = toy_character(**preset)
    sk = c.skeleton
    assert set(TOY_BONES) <= set(sk.names)
    assert sk.parents[sk.index("head")] == sk.index("neck_01")
    assert sk.parents[sk.index("neck_01")] == sk.index("spine_03")
    assert sk.parents[sk.index("upperarm_l")] == sk.index("clavicle_l")
    assert sk.heads[sk.index("upperarm_l")][0] > 0 > sk.heads[sk.index("upperarm_r")][0]  # left = +X
    t = np.linspace(0.02, 0.98, 25)[:, None]
    for b in range(sk.n_bones):
        samples = sk.heads[b] + t * (sk.tails[b] - sk.heads[b])
        assert igl.fast_winding_number(c.vertices, c.faces, samples).min() > 0.5, sk.names[b]
    # the head bone runs up through the head to near its top
    head = sk.index("head")
    assert sk.tails[head][1] > sk.heads[head][1]
    assert c.vertices[:, 1].max() - sk.tails[head][1] < 0.03
    rows = np.asarray(c.weights.sum(axis=1)).ravel()
    np.testing.assert_allclose(rows, 1.0, atol=1e-12)
    assert c.weights.min() >= 0
    head_w = c.weights[:, head].toarray().ravel()
    top = c.vertices[:, 1] > sk.tails[head][1] - 0.05
    assert head_w[top].min() == 1.0
    assert head_w[c.vertices[:, 1] < sk.heads[sk.index("neck_01")][1]].max() == 0.0


def test_toy_counts():
    toy = toy_character()
    assert toy.n_vertices == TOY_RINGS * TOY_RING_VERTICES + 2  # the rings and two poles
    # two triangles per quad between neighbouring rings, one fan at each pole
    assert toy.n_faces == 2 * TOY_RING_VERTICES * (TOY_RINGS - 1) + 2 * TOY_RING_VERTICES
    assert toy.skeleton.names == TOY_BONES and toy.weights.shape == (toy.n_vertices, len(TOY_BONES))
    assert toy.name == "toy" and toy_character(name="other").name == "other"


def test_toy_refuses_sizes_that_are_not_positive():
    for bad in (dict(neck_radius=0.0), dict(head_scale=(1.0, -1.0, 1.0)), dict(shoulder_width=-0.1)):
        with pytest.raises(ValueError, match="sizes must be positive"):
            toy_character(**bad)
