"""The single-level solves of Eq. 1 under Eq. 12-13: which active-set level, which QP backend.

* :func:`solve_strands`: the active-set loop (:mod:`.loop.active_set`) over a strand problem, on
  the level its ``K`` and the engine ask for: the compiled per-strand kernels of the fine level
  (:mod:`.fine.fine_solve`) when ``K`` is diagonal, else the numpy level
  (:mod:`.coupled.numpy_level`), which is also the compiled one's reference;
* :func:`solve_hairstyle`: a whole coupled hairstyle (the ``global`` method, and the guides of the
  multi-scale solve) by the chosen QP backend, the active-set loop or OSQP (:mod:`.coupled.osqp_backend`).

The choice sits above both levels: a coupled problem whose ``K`` turns out diagonal (a single
guide, guides without neighbours) is solved strand by strand on the compiled kernels.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import numpy as np

from hairport.solver.adaptation.coupled import osqp_backend
from hairport.solver.adaptation.coupled.numpy_level import NumpyLevel
from hairport.solver.adaptation.fine.fine_solve import CompiledLevel, pull_weights
from hairport.solver.adaptation.loop import active_set
from hairport.solver.adaptation.loop.active_set import run_active_set
from hairport.solver.adaptation.loop.options import (
    ENGINE_COMPILED,
    ENGINES,
    SEGMENT_ITERATIONS,
    SolveOptions,
    SolveReport,
)
from hairport.solver.adaptation.problem.constraints import BodyDistance
from hairport.solver.adaptation.problem.energies import EnergyWeights, ShapeModel
from hairport.solver.adaptation.problem.strand_problem import StrandProblem, problem_from_shape_model
from hairport.solver.adaptation.segments import clear_segments
from hairport.solver.mesh.distance_grid import DistanceGrid
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.progress import ProgressFn

#: how the coupled QPs are solved: the strand-banded active-set method (the default) or OSQP
QP_BACKENDS = (active_set.BACKEND, osqp_backend.BACKEND)


def solve_strands(
    problem: StrandProblem,
    distance: BodyDistance,
    weights: EnergyWeights = EnergyWeights(),
    options: SolveOptions = SolveOptions(),
    start: np.ndarray | None = None,
    progress: ProgressFn | None = None,
    should_stop: Callable[[], bool] | None = None,
    engine: str = ENGINE_COMPILED,
) -> tuple[np.ndarray, SolveReport]:
    """Minimise Eq. 1 under Eq. 12-13 by the active-set loop (:func:`.loop.active_set.run_active_set`), then
    the strands with a segment through the body again with margins (:func:`.segments.clear_segments`).

    Uncoupled strands each run the loop on their own, with their own merit penalty (so a strand's
    result does not depend on the strands solved with it); with a diagonal ``K`` the compiled level
    (:class:`.fine.fine_solve.CompiledLevel`) runs it unless ``engine`` asks for the numpy level
    (:class:`.coupled.numpy_level.NumpyLevel`), its reference, which solves every other ``K``.

    Parameters
    ----------
    problem : StrandProblem
    distance : BodyDistance
        Over the target body.
    weights : EnergyWeights
    options : SolveOptions
        ``eps_c``, ``max_iterations``, ``step_tolerance``, ``clearance_tolerance``, ...
    start : (N, 3) float64, optional
        First iterate (``problem.initial`` by default).
    progress : ProgressFn, optional
        ``progress("solve", fraction, message)`` after every outer iteration.
    should_stop : callable() -> bool, optional
        Polled once per outer iteration; True raises :class:`.loop.options.Cancelled`.
    engine : str
        One of :data:`.loop.options.ENGINES`: ``"compiled"`` (a diagonal ``K`` only; others take
        the numpy level) or ``"numpy"``.

    Returns
    -------
    points : (N, 3) float64
    report : SolveReport
        With the active-set fields (``groups``, ``active_set_rounds``, ...).
    """
    if engine not in ENGINES:
        raise ValueError(f"unknown engine {engine!r}; expected one of {', '.join(ENGINES)}")
    began = time.perf_counter()
    level = _level(problem, engine)(problem, distance, weights, options, start)
    points, report = run_active_set(level, options, progress, should_stop, began)
    # pushed particles moved away from their last distance: the check queries them all again
    last_distance = level.distance if report.pushed_out == 0 else None
    points = clear_segments(problem, distance, options, points, report,
                            _solve_again(weights, options, engine, should_stop), last_distance)
    report.seconds = time.perf_counter() - began
    return points, report


def _level(problem: StrandProblem, engine: str) -> type:
    """The active-set level that solves ``problem``: compiled for a diagonal ``K`` unless ``engine`` is numpy."""
    compiled = engine == ENGINE_COMPILED and pull_weights(problem.coupling) is not None
    return CompiledLevel if compiled else NumpyLevel


def _solve_again(weights: EnergyWeights, options: SolveOptions, engine: str,
                 should_stop: Callable[[], bool] | None) -> Callable:
    """The :data:`.segments.SolveFn` of a solve: its active-set loop over a subset of its strands."""

    again = dataclasses.replace(options, max_iterations=min(options.max_iterations, SEGMENT_ITERATIONS))

    def solve(sub: StrandProblem, shifted: BodyDistance, start: np.ndarray) -> tuple[np.ndarray, SolveReport]:
        return run_active_set(_level(sub, engine)(sub, shifted, weights, again, start), again,
                              should_stop=should_stop)

    return solve


def solve_hairstyle(
    model: ShapeModel,
    offsets: np.ndarray,
    initial: np.ndarray,
    fixed: np.ndarray,
    target: MeshQuery,
    weights: EnergyWeights = EnergyWeights(),
    options: SolveOptions = SolveOptions(),
    gamma: np.ndarray | None = None,
    backend: str = active_set.BACKEND,
    start: np.ndarray | None = None,
    grid: DistanceGrid | None = None,
    band: float = np.inf,
    progress: ProgressFn | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> tuple[np.ndarray, SolveReport]:
    """Eq. 1 over a whole (coupled) hairstyle with the chosen QP backend.

    Parameters
    ----------
    model : ShapeModel
    offsets : (S+1,) int64
    initial : (N, 3) float64
    fixed : (N,) bool
    target : MeshQuery
    backend : str
        One of :data:`QP_BACKENDS`.
    start : (N, 3) float64, optional
        First iterate (``initial`` by default); fixed particles stay where it puts them.
    grid, band
        Broad phase, see :class:`.problem.constraints.BodyDistance` (active-set backend only).
    progress : ProgressFn, optional
        ``progress("solve", fraction, message)`` after every outer iteration.

    Returns
    -------
    points : (N, 3) float64
    report : SolveReport
        ``report.backend`` is ``backend``.

    Raises
    ------
    ValueError
        For a backend not in :data:`QP_BACKENDS`.
    """
    if backend not in QP_BACKENDS:
        raise ValueError(f"unknown QP backend {backend!r}; expected one of {', '.join(QP_BACKENDS)}")
    problem = problem_from_shape_model(model, offsets, initial, fixed, gamma)
    if backend == osqp_backend.BACKEND:
        points, report = osqp_backend.solve_shape_adaptation(
            model, initial, fixed, target, weights, options, gamma=gamma, start=start, progress=progress,
            should_stop=should_stop,
        )
        # the strands with a segment through the body are solved again by the active-set loop, which takes margins
        points = clear_segments(problem, BodyDistance(target, band, grid), options, points, report,
                                _solve_again(weights, options, ENGINE_COMPILED, should_stop))
        return points, report
    return solve_strands(
        problem, BodyDistance(target, band, grid), weights, options, start=start, progress=progress,
        should_stop=should_stop,
    )
