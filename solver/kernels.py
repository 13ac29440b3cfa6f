"""Every compiled kernel of the solver, and the warm-up that compiles them ahead of a first retarget.

The kernels are declared where they are used, with :func:`hairport.solver.jit.kernel` and
:func:`~hairport.solver.jit.parallel_kernel`; each module with kernels registers a small function
that calls them on tiny inputs (:func:`hairport.solver.jit.warms`). This module imports every such
module by name, so that :func:`warm_up` (``hairport warmup``, the worker at start, the Docker image's
build) and :func:`uncached_kernels` (the demo's first-run notice) cover them all, and so that the
import graph shows which modules compile code. ``tests/solver/test_kernels.py`` checks that no module
declaring a kernel is missing here.
"""

from __future__ import annotations

from hairport.solver import jit, metrics
from hairport.solver.adaptation.coupled import coupled_kernels
from hairport.solver.adaptation.fine import band_kernels, line_search_kernels, strand_kernels
from hairport.solver.adaptation.problem import merit_kernels, model_kernels, spacing
from hairport.solver.adaptation.source import kdtree, neighbours
from hairport.solver.jit import COLD_COMPILE_SECONDS, WarmUp, set_threads, threads
from hairport.solver.mesh import bvh_build, closest_kernels, distance_grid
from hairport.solver.render import strands
from hairport.solver.transfer import bone_rays, smoothing

__all__ = ["COLD_COMPILE_SECONDS", "MODULES", "WarmUp", "set_threads", "threads", "uncached_kernels", "warm_up"]

#: the modules that declare kernels
MODULES = (coupled_kernels, band_kernels, line_search_kernels, strand_kernels, merit_kernels, model_kernels, spacing,
           kdtree, neighbours, bvh_build, closest_kernels, distance_grid, metrics, bone_rays, smoothing, strands)


def warm_up() -> WarmUp:
    """Compile (or load from numba's on-disk cache) every kernel of :data:`MODULES` that a warmer calls."""
    return jit.run_warmers()


def uncached_kernels() -> tuple[int, int]:
    """How many of the solver's kernels have no machine code in numba's on-disk cache for their current
    source (the ones the next calls compile), and how many there are (:func:`hairport.solver.jit.count_uncached`).

    Returns
    -------
    uncached, declared : int
    """
    return jit.count_uncached()
