"""Compiled kernels: numba's settings for the solver, and the warm-up registry.

Every compiled kernel of the solver is declared with :func:`kernel` (serial) or
:func:`parallel_kernel` (``prange`` over independent strands or points). Both compile on
first call and keep the machine code in numba's on-disk cache (``cache=True``: beside the
module's source when that folder is writable, else under ``NUMBA_CACHE_DIR`` or the user's
cache folder), so only the first process on a machine pays for compilation.

Each module with kernels registers one small function with :func:`warms` that calls its
kernels on tiny inputs; :func:`run_warmers` runs those registered. This module sits below every
kernel and names none of them: :mod:`hairport.solver.kernels` imports every module that declares
kernels and warms them all (``hairport warmup``, the worker at start, the Docker image build), so
a user's first retarget does not wait for the compiler.

Kernels take and return plain contiguous numpy arrays (float64 math, int64 indices); the
numpy implementation of the same step stays beside each kernel as the tested reference.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass

#: idle kernel threads sleep: by default libgomp (numba's OpenMP layer) spins for
#: milliseconds after every parallel kernel, taking a core from the numpy code between
#: kernel calls (measured: a 10^5 multi-scale retarget used 27 s of CPU against 21 s, its
#: distance queries 7-12 s against 3 s of wall, ``bench/closest_point.py --retarget``).
#: Read when numba starts its threads (the first parallel kernel call); an explicit setting wins.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import numba  # noqa: E402 - after the thread policy

#: numba options shared by every kernel: on-disk cache, no GIL (callable from threads),
#: numpy's semantics for division by zero (inf/nan, no exception) so kernels match their
#: numpy references
KERNEL_OPTIONS = {"cache": True, "nogil": True, "error_model": "numpy"}

#: wall seconds :func:`hairport.solver.kernels.warm_up` takes on an empty cache (48 s measured on a shared
#: 2-core AMD EPYC, ``hairport warmup``, 2026-11-28): what a first run announces before it compiles
COLD_COMPILE_SECONDS = 50.0

_WARMERS: dict[str, Callable[[], None]] = {}
#: every dispatcher declared through :func:`kernel` or :func:`parallel_kernel`
_KERNELS: list = []


def _declare(options: dict, function):
    def decorate(python_function):
        dispatcher = numba.njit(**options)(python_function)
        _KERNELS.append(dispatcher)
        return dispatcher

    return decorate if function is None else decorate(function)


def kernel(function=None, **options):
    """``numba.njit`` with :data:`KERNEL_OPTIONS` (serial)."""
    return _declare({**KERNEL_OPTIONS, **options}, function)


def parallel_kernel(function=None, **options):
    """``numba.njit(parallel=True)`` with :data:`KERNEL_OPTIONS`: loops written with
    :data:`prange` run on numba's threads (:func:`set_threads`).

    A process that has run a parallel kernel must not ``fork()`` without ``exec`` (GNU
    OpenMP, numba's threading layer where it is installed, terminates such a child):
    Celery's prefork parent never solves, and the worker warms the kernels in each child.
    """
    return _declare({**KERNEL_OPTIONS, "parallel": True, **options}, function)


prange = numba.prange


def warms(function: Callable[[], None]) -> Callable[[], None]:
    """Register ``function()``, which calls its module's kernels on tiny inputs, under its module's name."""
    _WARMERS[function.__module__] = function
    return function


@dataclass(frozen=True)
class WarmUp:
    """What :func:`run_warmers` did.

    Attributes
    ----------
    seconds : dict of str -> float
        Wall-clock seconds per registered module.
    kernels : int
        Kernels declared.
    compiled, loaded : int
        Kernel signatures compiled in this process, and loaded from the on-disk cache.
    """

    seconds: dict[str, float]
    kernels: int
    compiled: int
    loaded: int


def _cache_counts() -> tuple[int, int]:
    compiled = loaded = 0
    for dispatcher in _KERNELS:
        compiled += sum(dispatcher.stats.cache_misses.values())
        loaded += sum(dispatcher.stats.cache_hits.values())
    return compiled, loaded


def count_uncached() -> tuple[int, int]:
    """How many kernels declared so far have no machine code in numba's on-disk cache for their
    current source (the ones the next calls compile), and how many are declared.

    Reads the cache's index files only (milliseconds). A kernel no warmer calls stays uncached
    after :func:`run_warmers`: callers compare with a share of the total.

    Returns
    -------
    uncached, declared : int
    """
    return sum(1 for dispatcher in _KERNELS if not _cached(dispatcher)), len(_KERNELS)


def _cached(dispatcher) -> bool:
    # numba has no public query for this: its cache object's index lists the signatures stored
    # for the source file's current stamp (empty when missing or stale)
    try:
        return bool(dispatcher._cache._cache_file._load_index())
    except (AttributeError, OSError, EOFError, ValueError):
        return True  # unknown: no false alarm


def run_warmers() -> WarmUp:
    """Compile (or load from the on-disk cache) the kernels of every module imported so far, by its
    registered warmer (:mod:`hairport.solver.kernels` imports them all)."""
    seconds = {}
    for name, function in sorted(_WARMERS.items()):
        began = time.perf_counter()
        function()
        seconds[name] = time.perf_counter() - began
    compiled, loaded = _cache_counts()
    return WarmUp(seconds, len(_KERNELS), compiled, loaded)


def threads() -> int:
    """Threads the parallel kernels use."""
    return numba.get_num_threads()


def set_threads(count: int) -> None:
    """Use ``count`` threads (1 .. the number numba started with) in the parallel kernels."""
    numba.set_num_threads(max(1, min(int(count), numba.config.NUMBA_NUM_THREADS)))
