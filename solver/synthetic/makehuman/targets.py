"""MakeHuman shape targets: the ``.target.gz`` files, parsed once per folder and cached.

A target file lists vertex offsets of the full base mesh, one line ``vertex dx dy dz``
(decimeters) per moved vertex. A :class:`TargetGroup` holds every target of one folder as
one set of concatenated arrays, cached as ``<assets>/parsed/targets-<folder>.npz``
(:mod:`.cache`); deltas are stored as integers of 1/:data:`TARGET_DELTA_SCALE` dm when
that is exact.
"""

from __future__ import annotations

import gzip
import io
from pathlib import Path

import numpy as np

from hairport.solver.model.errors import InputError
from hairport.solver.synthetic.assets import TARGETS_DIR
from hairport.solver.synthetic.makehuman.base_model import N_FULL_VERTICES
from hairport.solver.synthetic.makehuman.cache import PARSED_DIR, load_cache, save_cache

#: file name ending of a target file
TARGET_SUFFIX = ".target.gz"

TARGET_DELTA_SCALE = 1000
"""Target deltas are written with at most 3 decimals (1e-4 m); they are cached as integers
of 1/1000 dm and divided back exactly (same doubles as parsing the text)."""


def target_files(assets: Path, group: str) -> list[Path]:
    """The target files of folder ``group`` (e.g. ``"head"``) under ``<assets>/targets/``, sorted by path."""
    return sorted((assets / TARGETS_DIR / group).glob(f"*{TARGET_SUFFIX}"))


def target_name(group: str, path: Path) -> str:
    """A target's name: ``group/stem``, its path under ``targets/`` without the extension."""
    return f"{group}/{path.name[: -len(TARGET_SUFFIX)]}"


def read_target_file(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Parse one ``.target.gz``: lines ``vertex dx dy dz`` (decimeters), ``#`` comments.

    Returns
    -------
    indices : (K,) int64
    deltas : (K, 3) float64
    """
    with gzip.open(path, "rb") as handle:
        raw = handle.read()
    if not any(line.strip() and not line.lstrip().startswith(b"#") for line in raw.splitlines()):
        return np.zeros(0, np.int64), np.zeros((0, 3))
    table = np.loadtxt(io.BytesIO(raw), comments="#", ndmin=2, dtype=np.float64)
    if table.shape[1] != 4:
        raise InputError(f"expected 4 columns, found {table.shape[1]}", str(path), "bad_target")
    indices = table[:, 0].astype(np.int64)
    if indices.min() < 0 or indices.max() >= N_FULL_VERTICES or not np.array_equal(indices, table[:, 0]):
        raise InputError("vertex index out of range", str(path), "bad_target")
    deltas = table[:, 1:]
    unique, inverse = np.unique(indices, return_inverse=True)
    if len(unique) != len(indices):  # none in the shipped files; sum repeated lines
        summed = np.zeros((len(unique), 3))
        np.add.at(summed, inverse, deltas)
        indices, deltas = unique, summed
    return indices, deltas


class TargetGroup:
    """All targets of one folder, parsed once and cached as one ``.npz``.

    Attributes
    ----------
    names : tuple of str
        Target names (``group/stem``).
    offsets : (T+1,) int64
        Target ``t`` covers rows ``offsets[t]:offsets[t+1]`` of ``indices``/``deltas``.
    indices : (K,) uint16 or int64
    deltas : (K, 3) int16/int32 (1/1000 dm) or float64 (dm)
    """

    def __init__(self, assets: Path, group: str):
        files = target_files(assets, group)
        self.group = group
        self.names = tuple(target_name(group, p) for p in files)
        cache = assets / PARSED_DIR / f"targets-{group.replace('/', '-')}.npz"
        arrays = load_cache(cache)
        if arrays is None or tuple(arrays["names"].tolist()) != self.names:
            arrays = self._parse(files)
            save_cache(cache, arrays)
        self.offsets = arrays["offsets"]
        self.indices = arrays["indices"]
        self.deltas = arrays["deltas"]
        self.quantized = bool(arrays["quantized"])
        self._row = {name: i for i, name in enumerate(self.names)}

    def _parse(self, files: list[Path]) -> dict[str, np.ndarray]:
        parsed = [read_target_file(p) for p in files]
        counts = np.array([len(i) for i, _ in parsed], dtype=np.int64)
        offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
        indices = np.concatenate([i for i, _ in parsed]) if parsed else np.zeros(0, np.int64)
        deltas = np.concatenate([d for _, d in parsed]) if parsed else np.zeros((0, 3))
        quantized = np.rint(deltas * TARGET_DELTA_SCALE)
        exact = np.array_equal(quantized / TARGET_DELTA_SCALE, deltas)
        if exact:
            limit = np.abs(quantized).max(initial=0)
            deltas_out = quantized.astype(np.int16 if limit < np.iinfo(np.int16).max else np.int32)
        else:
            deltas_out = deltas
        return {
            "names": np.array(self.names, dtype=str),
            "offsets": offsets,
            "indices": indices.astype(np.uint16),
            "deltas": deltas_out,
            "quantized": np.bool_(exact),
        }

    def __contains__(self, name: str) -> bool:
        return name in self._row

    def add_to(self, out: np.ndarray, name: str, weight: float) -> None:
        """``out[indices] += weight * deltas`` of target ``name``; out (N, 3) float64, dm."""
        row = self._row[name]
        lo, hi = self.offsets[row], self.offsets[row + 1]
        if hi == lo:
            return
        deltas = self.deltas[lo:hi].astype(np.float64)
        if self.quantized:
            deltas /= TARGET_DELTA_SCALE
        out[self.indices[lo:hi].astype(np.intp)] += weight * deltas
