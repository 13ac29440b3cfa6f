"""The per-target cache: what a retarget needs of the target body alone, built once per body and kept in the
shared storage for every job and every worker, keyed by the body's content (like the artifacts of
preprocessing).

What is kept is the body's collision surface (the faces that separate its inside from outside, a winding
number at two points per face: ~0.3 s on the 27k-face MakeHuman body, growing with the faces). The rest of
what a retarget builds of the target is cheaper or not the body's alone: the closest-point trees (~0.06 s),
the skeleton transferred to an unrigged target (~0.06 s, and it depends on the source), the distance grid
(it covers the region of the groom's initial transfer). Within a worker process the solver also keeps the
last bodies' queries in memory.
"""

from __future__ import annotations

import time

import numpy as np

from hairport import solver
from hairport.records import BodyRecord, now
from hairport.repository import Repository
from hairport.settings import Settings

#: the job timings' entries: the surface built here (and kept), or read from the cache
BUILT, LOADED = "target_cache_build", "target_cache_load"


def collision_surface(repository: Repository, settings: Settings,
                      target: solver.Character) -> tuple[np.ndarray | None, dict[str, float]]:
    """The target's collision surface, ``(F,) bool``, from the cache or built and kept (None with the cache off:
    the solver builds it), and the seconds it took under :data:`BUILT` or :data:`LOADED`."""
    if not settings.target_cache:
        return None, {}
    began = time.perf_counter()
    key = solver.body_key(target.vertices, target.faces)
    record = repository.get(BodyRecord, key)
    blob = None if record is None else repository.storage.blob(record.sha256, record.suffix)
    if blob is not None:
        separating = np.load(blob.path, allow_pickle=False)
        if separating.dtype == bool and separating.shape == (target.n_faces,):
            return separating, {LOADED: time.perf_counter() - began}
    separating = solver.collision_faces(target.vertices, target.faces, target.name)
    seconds = time.perf_counter() - began
    saved = repository.storage.save_written(lambda path: np.save(path, separating), ".npy")
    repository.put(BodyRecord(key=key, sha256=saved.sha256, faces=target.n_faces, seconds=seconds,
                              created_at=now()), key)
    return separating, {BUILT: time.perf_counter() - began}
