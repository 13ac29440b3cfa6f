"""The wrap cache: the source body wrapped onto a target of another topology, made once and kept in the shared
storage for every job and every worker, keyed by the wrap's content key (:func:`hairport.solver.wrap_key`: both
bodies, the part of the source the groom's hair reaches, the wrap's options), like the per-target collision
surfaces of :mod:`.bodies`.

What is kept is what a retarget needs of the wrap (:class:`hairport.solver.WrappedTarget`): the wrapped
vertices, ``(V, 3) float64`` (the faces are the source's, in the artifact), and the wrap's report (the metrics'
``wrap`` section), in one ``.npz`` blob. A wrap takes ~1-6 s on a 5k-vertex target (the more of the body the hair
reaches, the longer); reading it back, milliseconds. Two jobs that start the same wrap at once both make it (the
same content: the later record wins); every later job reads it.

The key holds the region the hair reaches, so each groom has its own wrap of a target: another groom's,
fitted over another part of the body, would move its result by millimetres (a result does not depend on which
job ran first).
"""

from __future__ import annotations

import json
import time

import numpy as np

from hairport import solver
from hairport.outputs import json_default
from hairport.records import WrapRecord, now
from hairport.repository import Repository
from hairport.settings import Settings

#: the job timings' entries: the wrap read from the cache, or kept there after the retarget made it (the wrap
#: itself is the retarget's ``wrap`` timing)
LOADED, STORED = "wrap_cache_load", "wrap_cache_store"
#: the progress stage of a wrap (the retarget's own, for one it makes)
WRAP_STAGE = "wrap"


def cached_wrap(repository: Repository, settings: Settings, adaptable: solver.AdaptableHairstyle,
                target: solver.Character, mode: str, progress: solver.ProgressFn = solver.no_progress,
                landmarks: solver.LandmarkPairs | None = None) -> tuple[solver.WrappedTarget | None, dict[str, float]]:
    """The wrap a retarget of ``adaptable`` onto ``target`` needs, from the cache, and the seconds reading it took
    under :data:`LOADED`; None (the retarget wraps) when it needs none, the cache is off or holds no usable one.

    Parameters
    ----------
    target : Character
        Canonical frame.
    mode : str
        The retarget's ``options.wrap``.
    landmarks : LandmarkPairs, optional
        The retarget's ``options.landmarks`` (canonical frame): part of the wrap's key.
    """
    if not settings.target_cache or not solver.needs_wrap(adaptable.source, target, mode):
        return None, {}
    began = time.perf_counter()
    key = solver.wrap_key(adaptable, target, landmarks=landmarks)
    record = repository.get(WrapRecord, key)
    blob = None if record is None else repository.storage.blob(record.sha256, record.suffix)
    if blob is None:
        return None, {}
    with np.load(blob.path, allow_pickle=False) as stored:
        vertices, report = stored["vertices"], json.loads(str(stored["report"]))
    if vertices.dtype != np.float64 or vertices.shape != (adaptable.source.n_vertices, 3):
        return None, {}  # a damaged or foreign file: wrapped again, and kept again
    progress(WRAP_STAGE, 0.0, f"the source body wrapped onto the target ({target.n_vertices:,} vertices), from the "
                              "cache")
    shape = solver.Character(vertices, adaptable.source.faces, name=f"{target.name or 'target'} (wrapped)")
    return solver.WrappedTarget(shape, key, report), {LOADED: time.perf_counter() - began}


def keep(repository: Repository, settings: Settings, wrapped: solver.WrappedTarget | None) -> dict[str, float]:
    """Keep a wrap a retarget made (``RetargetResult.wrapped``) under its key, and the seconds it took under
    :data:`STORED` (nothing for no wrap, or with the cache off)."""
    if wrapped is None or not settings.target_cache:
        return {}
    began = time.perf_counter()
    saved = repository.storage.save_written(lambda path: np.savez(
        path, vertices=np.asarray(wrapped.shape.vertices, dtype=np.float64),
        report=np.array(json.dumps(wrapped.report, default=json_default))), ".npz")
    repository.put(WrapRecord(key=wrapped.key, sha256=saved.sha256, vertices=wrapped.shape.n_vertices,
                              seconds=float(wrapped.report.get("seconds", 0.0)), created_at=now()), wrapped.key)
    return {STORED: time.perf_counter() - began}
