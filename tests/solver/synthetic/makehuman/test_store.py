"""Tests for solver/synthetic/makehuman/store.py: the parsed assets kept per process, the shape targets they offer."""

from __future__ import annotations

import pytest

from hairport.solver.model.errors import InputError
from hairport.solver.synthetic.assets import SHAPE_TARGET_GROUPS
from hairport.solver.synthetic.makehuman import PRESETS, MakeHumanParams, build_character
from hairport.solver.synthetic.makehuman.store import asset_store, available_targets


def test_extra_targets_are_checked_against_the_assets(assets):
    with pytest.raises(InputError, match="head/head-round"):  # suggests the close match
        build_character(MakeHumanParams(targets={"head/head-rond": 0.5}), assets)
    names = available_targets(assets)
    assert "head/head-round" in names and "neck/neck-scale-horiz-incr" in names
    for preset in PRESETS.values():
        assert all(name in names for name, _ in preset.targets)


def test_one_store_per_assets_directory(assets, tmp_path):
    store = asset_store(assets)
    assert asset_store(assets / "targets" / "..") is store  # the path is resolved
    assert store.model is store.model and store.group("head") is store.group("head")
    with pytest.raises(InputError) as error:
        asset_store(tmp_path)
    assert error.value.code == "missing_assets" and "3dobjs/base.obj" in error.value.problem


def test_available_targets_are_the_shape_targets(assets):
    names = available_targets(assets)
    folders = [name.split("/")[0] for name in names]
    assert set(folders) <= set(SHAPE_TARGET_GROUPS) and "macrodetails" not in folders
    # grouped by folder in the order of SHAPE_TARGET_GROUPS, sorted within a folder
    assert folders == sorted(folders, key=SHAPE_TARGET_GROUPS.index)
    head = [name for name in names if name.startswith("head/")]
    assert head == sorted(head) and len(head) == len(list((assets / "targets" / "head").glob("*.target.gz")))
