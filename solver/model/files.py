"""Files written whole or not at all: the one atomic write of hairport.

Every writer of a result, an artifact, a sidecar or a stored record goes through
:func:`atomic_write`: the bytes go to a new temporary file in the destination's folder (same
file system), which is renamed over the destination only when complete, so a reader in any
process sees the old file or the new one, never a partial one, and a failed write leaves
nothing behind.
"""

from __future__ import annotations

import contextlib
import os
import secrets
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

#: mode of new files before the umask: readable by the other processes of a deployment
FILE_MODE = 0o666
#: temporary files are ``.<name>.<random hex>.tmp`` beside their destination
TEMP_SUFFIX = ".tmp"
#: random bytes in a temporary file name (hex-encoded: twice as many characters)
TEMP_NAME_BYTES = 6


def atomic_write(path: str | os.PathLike, write: Callable[[BinaryIO], None], *, durable: bool = True) -> Path:
    """Write ``path`` through ``write(handle)``, atomically.

    Parameters
    ----------
    path : path-like
        The destination; its folder must exist.
    write : callable(binary file handle)
        Writes the whole content.
    durable : bool
        ``fsync`` the file before the rename and its folder after it, so that the new
        content survives a crash of the machine (off only for scratch data).

    Returns
    -------
    path : Path
    """
    path = Path(path)
    folder = path.parent
    while True:
        temporary = folder / f".{path.name}.{secrets.token_hex(TEMP_NAME_BYTES)}{TEMP_SUFFIX}"
        try:
            fd = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), FILE_MODE)
            break
        except FileExistsError:
            continue
    try:
        with os.fdopen(fd, "wb") as handle:
            write(handle)
            handle.flush()
            if durable:
                os.fsync(handle.fileno())
        os.replace(temporary, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temporary)
        raise
    if durable:
        fsync_folder(folder)
    return path


def atomic_write_bytes(path: str | os.PathLike, data: bytes, *, durable: bool = True) -> Path:
    """:func:`atomic_write` of ``data``."""
    return atomic_write(path, lambda handle: handle.write(data), durable=durable)


def fsync_folder(folder: str | os.PathLike) -> None:
    """Make a rename in ``folder`` durable (where the platform allows opening folders)."""
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
