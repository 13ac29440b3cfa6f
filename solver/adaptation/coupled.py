"""Eq. 1 over a whole coupled hairstyle (the ``global`` method, and the guides of the multi-scale
solve), by the chosen QP backend: :mod:`.active_set` or :mod:`.osqp_backend`."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hairport.solver.adaptation import active_set, osqp_backend
from hairport.solver.adaptation.constraints import BodyDistance
from hairport.solver.adaptation.energies import EnergyWeights, ShapeModel
from hairport.solver.adaptation.options import SolveOptions, SolveReport
from hairport.solver.adaptation.strand_problem import problem_from_shape_model
from hairport.solver.mesh.distance_grid import DistanceGrid
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.progress import ProgressFn

#: how the coupled QPs are solved: the strand-banded active-set method (the default) or OSQP
QP_BACKENDS = (active_set.BACKEND, osqp_backend.BACKEND)


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
        Broad phase, see :class:`.constraints.BodyDistance` (active-set backend only).
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
    if backend == osqp_backend.BACKEND:
        return osqp_backend.solve_shape_adaptation(
            model, initial, fixed, target, weights, options, gamma=gamma, start=start, progress=progress,
            should_stop=should_stop,
        )
    if backend != active_set.BACKEND:
        raise ValueError(f"unknown QP backend {backend!r}; expected one of {', '.join(QP_BACKENDS)}")
    problem = problem_from_shape_model(model, offsets, initial, fixed, gamma)
    return active_set.solve_strands(
        problem, BodyDistance(target, band, grid), weights, options, start=start, progress=progress,
        should_stop=should_stop,
    )
