"""The ``.npz`` caches of parsed MakeHuman assets under ``<assets>/parsed/``.

Parsing the target files and the base model takes ~7 s once; the arrays are then kept as
``.npz`` files beside the assets. A cache written by another layout (:data:`CACHE_FORMAT`),
or one that cannot be read, counts as missing, and a cache that cannot be written (a
read-only assets folder) is skipped: the builder then works from memory.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from hairport.solver.model.files import atomic_write

#: folder of the caches, under the assets directory
PARSED_DIR = "parsed"
#: bump when the layout of the ``parsed/*.npz`` caches changes
CACHE_FORMAT = 1
#: the array holding :data:`CACHE_FORMAT` in every cache
FORMAT_KEY = "cache_format"


def load_cache(path: Path) -> dict[str, np.ndarray] | None:
    """The arrays of a cache, or ``None`` when it is missing, unreadable or of another format.

    Parameters
    ----------
    path : Path

    Returns
    -------
    arrays : dict of str to ndarray or None
        Including :data:`FORMAT_KEY`.
    """
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except (OSError, ValueError, KeyError, EOFError):
        return None
    if int(arrays.get(FORMAT_KEY, -1)) != CACHE_FORMAT:
        return None
    return arrays


def save_cache(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write a cache atomically (not fsynced: it can be rebuilt); do nothing if that fails.

    Parameters
    ----------
    path : Path
        The folder is created if needed.
    arrays : dict of str to ndarray
    """
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(path, lambda handle: np.savez(handle, **{FORMAT_KEY: np.int64(CACHE_FORMAT)}, **arrays),
                     durable=False)
    except OSError:
        pass  # read-only cache: keep working from memory
