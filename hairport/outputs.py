"""All-or-nothing output files: everything is written to temporary names first and renamed
into place only when every file succeeded, so a failed run leaves no partial output.

Every output gets one file mode, the solver's ``FILE_MODE`` less the umask (0644 under the
usual umask 022): the temporary file is created with it, and writers that write into it (the
report, the preview) keep it, as does the atomic write that replaces it (the hair, the artifact).
"""

from __future__ import annotations

import json
import os
import secrets
from collections.abc import Callable
from pathlib import Path

import numpy as np

from hairport.solver import FILE_MODE

#: random bytes in a temporary output's name (hex-encoded: twice as many characters)
TEMP_NAME_BYTES = 6


class OutputSet:
    """Collect output files, then :meth:`commit` them together (or :meth:`abort`)."""

    def __init__(self) -> None:
        self._pending: list[tuple[Path, Path]] = []

    def add(self, final: str | os.PathLike, write: Callable[[Path], None]) -> None:
        """Write ``final`` through ``write(temporary_path)``; the file appears only on commit."""
        final = Path(final)
        final.parent.mkdir(parents=True, exist_ok=True)
        temporary = _create_temporary(final)
        self._pending.append((temporary, final))
        write(temporary)

    def add_json(self, final: str | os.PathLike, document: dict) -> None:
        self.add(final, lambda path: path.write_text(json.dumps(document, indent=2, default=json_default) + "\n"))

    def commit(self) -> list[Path]:
        for temporary, final in self._pending:
            os.replace(temporary, final)
        done = [final for _, final in self._pending]
        self._pending.clear()
        return done

    def abort(self) -> None:
        for temporary, _ in self._pending:
            temporary.unlink(missing_ok=True)
        self._pending.clear()

    def __enter__(self) -> "OutputSet":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            self.abort()


def _create_temporary(final: Path) -> Path:
    """A new empty file beside ``final`` with the mode every output has (not mkstemp's 0600)."""
    while True:
        # the temporary name keeps the extension, so writers that infer the format from it still work
        temporary = final.parent / f".{final.stem}.{secrets.token_hex(TEMP_NAME_BYTES)}.part{final.suffix}"
        try:
            os.close(os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), FILE_MODE))
            return temporary
        except FileExistsError:
            continue


def json_default(value):
    """``json.dumps`` fallback for numpy scalars and arrays."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
