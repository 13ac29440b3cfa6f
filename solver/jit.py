"""Compiled kernels: numba's settings for the solver, and the warm-up registry.

Every compiled kernel of the solver is declared with :func:`kernel` (serial) or
:func:`parallel_kernel` (``prange`` over independent strands or points). Both compile on
first call and keep the machine code in numba's on-disk cache (``cache=True``: beside the
module's source when that folder is writable, else under ``NUMBA_CACHE_DIR`` or the user's
cache folder), so only the first process on a machine pays for compilation.

Each module with kernels registers one small function with :func:`warms` that calls its
kernels on tiny inputs; :func:`warm_up` runs them all (``hairport warmup``, the worker at
start, the Docker image build), so a user's first retarget does not wait for the compiler.

Kernels take and return plain contiguous numpy arrays (float64 math, int64 indices); the
numpy implementation of the same step stays beside each kernel as the tested reference.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numba

#: numba options shared by every kernel: on-disk cache, no GIL (callable from threads),
#: numpy's semantics for division by zero (inf/nan, no exception) so kernels match their
#: numpy references
KERNEL_OPTIONS = {"cache": True, "nogil": True, "error_model": "numpy"}

_WARMERS: dict[str, Callable[[], None]] = {}


def kernel(function=None, **options):
    """``numba.njit`` with :data:`KERNEL_OPTIONS` (serial)."""
    decorate = numba.njit(**{**KERNEL_OPTIONS, **options})
    return decorate if function is None else decorate(function)


def parallel_kernel(function=None, **options):
    """``numba.njit(parallel=True)`` with :data:`KERNEL_OPTIONS`: loops written with
    :data:`prange` run on numba's threads (:func:`set_threads`)."""
    decorate = numba.njit(**{**KERNEL_OPTIONS, "parallel": True, **options})
    return decorate if function is None else decorate(function)


prange = numba.prange


def warms(name: str):
    """Register ``function()``, which calls some kernels on tiny inputs, under ``name``."""

    def register(function: Callable[[], None]) -> Callable[[], None]:
        _WARMERS[name] = function
        return function

    return register


def _import_kernel_modules() -> None:
    # the modules register their warmers when imported
    import importlib

    for module in KERNEL_MODULES:
        importlib.import_module(module)


#: modules that declare kernels (imported by :func:`warm_up`)
KERNEL_MODULES: tuple[str, ...] = ("hairport.solver.adaptation.kdtree", "hairport.solver.adaptation.neighbours", "hairport.solver.transfer.bone_rays", "hairport.solver.metrics",
                                   "hairport.solver.transfer.smoothing")


def warm_up() -> dict[str, float]:
    """Compile (or load from the on-disk cache) every registered kernel.

    Returns
    -------
    seconds : dict of str -> float
        Wall-clock seconds per registered module.
    """
    _import_kernel_modules()
    seconds = {}
    for name, function in sorted(_WARMERS.items()):
        began = time.perf_counter()
        function()
        seconds[name] = time.perf_counter() - began
    return seconds


def threads() -> int:
    """Threads the parallel kernels use."""
    return numba.get_num_threads()


def set_threads(count: int) -> None:
    """Use ``count`` threads (1 .. the number numba started with) in the parallel kernels."""
    numba.set_num_threads(max(1, min(int(count), numba.config.NUMBA_NUM_THREADS)))
