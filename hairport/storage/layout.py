"""Names, paths and file helpers of the storage layout (see :mod:`hairport.storage`)."""

from __future__ import annotations

import os
import re
import secrets
from pathlib import Path

from hairport.solver import FILE_MODE, TEMP_SUFFIX

#: hex characters of the fan-out directory of a blob (256 directories)
BLOB_FANOUT_CHARS = 2
#: hex characters of a SHA-256 digest
SHA256_HEX_CHARS = 64
#: seconds in a day (``Settings.retention_days`` -> :meth:`LocalStorage.purge`)
SECONDS_PER_DAY = 86_400.0
#: random bytes in a temporary file name (hex-encoded: twice as many characters)
TEMP_NAME_BYTES = 8

RECORD_SUFFIX = ".json"
LOCK_SUFFIX = ".lock"

#: record kinds and ids: file names never come from user input unchecked
NAME_PATTERN = re.compile(r"[a-z0-9_-]{1,64}")
SHA256_PATTERN = re.compile(r"[0-9a-f]{64}")
#: blob suffixes: ``""`` or one or more ``.ext`` parts, at most 32 characters
SUFFIX_PATTERN = re.compile(r"(\.[A-Za-z0-9_-]+)*")
SUFFIX_MAX_CHARS = 32


def retention_seconds(days: float) -> float:
    """``Settings.retention_days`` in seconds, the argument of :meth:`LocalStorage.purge`."""
    return days * SECONDS_PER_DAY


def check_name(value: str, what: str = "name") -> str:
    """``value`` if it matches :data:`NAME_PATTERN`, else ``ValueError``."""
    if not isinstance(value, str) or not NAME_PATTERN.fullmatch(value):
        raise ValueError(f"invalid {what} {value!r}: expected 1 to 64 of a-z, 0-9, '_', '-'")
    return value


def check_sha256(value: str) -> str:
    """``value`` if it is 64 lower-case hex characters, else ``ValueError``."""
    if not isinstance(value, str) or not SHA256_PATTERN.fullmatch(value):
        raise ValueError(f"invalid sha256 {value!r}: expected 64 lower-case hex characters")
    return value


def check_suffix(value: str) -> str:
    """``value`` if it is ``""`` or like ``".obj"`` / ``".tar.gz"`` (no path separators), else ``ValueError``."""
    if not isinstance(value, str) or len(value) > SUFFIX_MAX_CHARS or not SUFFIX_PATTERN.fullmatch(value):
        raise ValueError(f"invalid blob suffix {value!r}: expected '' or '.ext' parts of a-z, A-Z, 0-9, '_', '-'")
    return value


def blob_relpath(sha256: str, suffix: str = "") -> str:
    """``blobs/<aa>/<sha256><suffix>`` relative to the storage root."""
    return f"blobs/{sha256[:BLOB_FANOUT_CHARS]}/{sha256}{suffix}"


def blob_references(document) -> set[str]:
    """Every ``"sha256"`` string value found at any depth of a JSON document."""
    found: set[str] = set()
    stack = [document]
    while stack:
        item = stack.pop()
        if isinstance(item, dict):
            value = item.get("sha256")
            if isinstance(value, str):
                found.add(value)
            stack.extend(item.values())
        elif isinstance(item, list):
            stack.extend(item)
    return found


def _create_temp(folder: Path, prefix: str) -> tuple[int, Path]:
    """A new empty file in ``folder`` (mode :data:`FILE_MODE` minus the umask), opened for writing."""
    while True:
        path = folder / f"{prefix}{secrets.token_hex(TEMP_NAME_BYTES)}{TEMP_SUFFIX}"
        try:
            return os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, FILE_MODE), path
        except FileExistsError:
            continue


def _unlink(path: Path) -> bool:
    """Remove a file; whether it was there."""
    try:
        path.unlink()
        return True
    except FileNotFoundError:
        return False


def _mtime(path: Path) -> float | None:
    try:
        return path.stat().st_mtime
    except FileNotFoundError:
        return None


def _read_text(path: Path) -> str | None:
    try:
        return path.read_text()
    except FileNotFoundError:
        return None


def _files(folder: Path) -> list[Path]:
    """Regular files directly in ``folder`` (none if it does not exist)."""
    try:
        with os.scandir(folder) as entries:
            return [Path(entry.path) for entry in entries if entry.is_file(follow_symlinks=False)]
    except FileNotFoundError:
        return []


def _subdirs(folder: Path) -> list[Path]:
    try:
        with os.scandir(folder) as entries:
            return [Path(entry.path) for entry in entries if entry.is_dir(follow_symlinks=False)]
    except FileNotFoundError:
        return []


def _is_old(path: Path, cutoff: float) -> bool:
    """Whether ``path`` exists with an mtime before ``cutoff`` (checked right before a removal)."""
    mtime = _mtime(path)
    return mtime is not None and mtime < cutoff


def _tree_stats(folder: Path) -> tuple[int, float]:
    """Number of files under ``folder`` and the newest mtime of it and everything in it."""
    files = 0
    newest = _mtime(folder) or 0.0
    for parent, dirs, names in os.walk(folder):
        for name in dirs + names:
            newest = max(newest, _mtime(Path(parent) / name) or 0.0)
        files += len(names)
    return files, newest
