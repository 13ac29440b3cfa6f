"""A real browser for the dashboard tests and bench: Debian's Chromium driven by Playwright (from PyPI, never
``playwright install``: browsers are not downloaded), with software WebGL (SwiftShader), and what the tests read
off its screenshots."""

from __future__ import annotations

import io
import os
import shutil
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

#: the browser: ``HAIRPORT_CHROMIUM`` or Debian's (``.ci/run`` installs it with apt-get)
CHROMIUM_CANDIDATES = ("chromium", "chromium-browser")
#: WebGL without a GPU: ANGLE over SwiftShader
SOFTWARE_WEBGL = ("--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist")
#: the root user of CI containers cannot use Chromium's sandbox
ARGS = (*SOFTWARE_WEBGL, "--no-sandbox")
#: where screenshots of each step go (kept after the run as test artefacts)
ARTIFACTS = Path(os.environ.get("HAIRPORT_TEST_ARTIFACTS", Path(__file__).parents[2] / "test-artifacts"))


def chromium_path() -> str:
    explicit = os.environ.get("HAIRPORT_CHROMIUM")
    found = explicit or next(filter(None, map(shutil.which, CHROMIUM_CANDIDATES)), None)
    if not found:
        pytest.fail("the dashboard tests need Chromium (Debian's chromium package; .ci/run installs it) or "
                    "HAIRPORT_CHROMIUM naming one")
    return found


@contextmanager
def chromium(viewport=(1280, 900)):
    """A headless Chromium page; the page's errors are collected in ``page.errors``."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=chromium_path(), args=list(ARGS), headless=True)
        try:
            page = browser.new_page(viewport={"width": viewport[0], "height": viewport[1]}, accept_downloads=True)
            page.errors = []
            page.on("pageerror", lambda error: page.errors.append(str(error)))
            yield page
        finally:
            browser.close()


def pixels(png: bytes) -> np.ndarray:
    """(H, W, 3) uint8 RGB of a screenshot."""
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))


def near(image: np.ndarray, rgb, tolerance: int) -> np.ndarray:
    """(H, W) bool: pixels within ``tolerance`` of ``rgb`` in every channel."""
    return np.all(np.abs(image.astype(np.int16) - np.asarray(rgb, dtype=np.int16)) <= tolerance, axis=2)


def count_near(image: np.ndarray, rgb, tolerance: int) -> int:
    """Pixels within ``tolerance`` of ``rgb`` in every channel."""
    return int(near(image, rgb, tolerance).sum())


def mean_column_near(image: np.ndarray, rgb, tolerance: int) -> float:
    """Mean x (as a fraction of the width) of the pixels within ``tolerance`` of ``rgb``; NaN if none."""
    columns = np.nonzero(near(image, rgb, tolerance))[1]
    return float(columns.mean() / image.shape[1]) if columns.size else float("nan")


def rows_near(image: np.ndarray, rgb, tolerance: int) -> np.ndarray:
    """Image rows holding pixels within ``tolerance`` of ``rgb``."""
    return np.flatnonzero(near(image, rgb, tolerance).any(axis=1))


def count_red(image: np.ndarray) -> int:
    """Strongly red pixels (the viewer's particles inside the body)."""
    red, green, blue = (image[..., channel].astype(np.int16) for channel in range(3))
    return int(((red > 170) & (green < 90) & (blue < 90)).sum())


def count_drawn(image: np.ndarray, background=(255, 255, 255)) -> int:
    """Pixels that are not the background."""
    return int(np.any(image != np.asarray(background, dtype=np.uint8), axis=2).sum())
