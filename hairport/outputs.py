"""All-or-nothing output files: everything is written to temporary names first and renamed
into place only when every file succeeded, so a failed run leaves no partial output."""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np


class OutputSet:
    """Collect output files, then :meth:`commit` them together (or :meth:`abort`)."""

    def __init__(self) -> None:
        self._pending: list[tuple[Path, Path]] = []

    def add(self, final: str | os.PathLike, write: Callable[[Path], None]) -> None:
        """Write ``final`` through ``write(temporary_path)``; the file appears only on commit."""
        final = Path(final)
        final.parent.mkdir(parents=True, exist_ok=True)
        # the temporary name keeps the extension, so writers that infer the format from it still work
        fd, name = tempfile.mkstemp(prefix=f".{final.stem}.", suffix=f".part{final.suffix}", dir=final.parent)
        os.close(fd)
        temporary = Path(name)
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


def json_default(value):
    """``json.dumps`` fallback for numpy scalars and arrays."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
