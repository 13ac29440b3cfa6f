"""Eq. 1 over a whole coupled hairstyle (the ``global`` method, and the guides of the multi-scale solve), with a chosen QP backend."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hairport.solver.adaptation.active_set import ProgressFn, solve_strands
from hairport.solver.adaptation.constraints import BodyDistance
from hairport.solver.adaptation.energies import EnergyWeights, ShapeModel
from hairport.solver.adaptation.options import SolveOptions
from hairport.solver.adaptation.strand_problem import problem_from_shape_model
from hairport.solver.mesh.query import MeshQuery

#: how the coupled QPs are solved: this module's active-set method, or OSQP (:mod:`.qp`)
QP_BACKENDS = ("active-set", "osqp")


def solve_hairstyle(
    model: ShapeModel,
    offsets: np.ndarray,
    initial: np.ndarray,
    fixed: np.ndarray,
    target: MeshQuery,
    weights: EnergyWeights = EnergyWeights(),
    options: SolveOptions = SolveOptions(),
    gamma: np.ndarray | None = None,
    backend: str = "active-set",
    start: np.ndarray | None = None,
    broad_phase: Callable[[np.ndarray], np.ndarray] | None = None,
    band: float = np.inf,
    progress: ProgressFn | None = None,
    should_stop: Callable[[], bool] | None = None,
):
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
    broad_phase, band
        See :class:`BodyDistance` (active-set backend only).

    Returns
    -------
    points : (N, 3) float64
    report : StrandSolveReport or .qp.SolveReport
    """
    if backend == "osqp":
        from hairport.solver.adaptation.osqp_backend import solve_shape_adaptation

        return solve_shape_adaptation(
            model, initial, fixed, target, weights, options, gamma=gamma, start=start, progress=progress,
            should_stop=should_stop,
        )
    if backend != "active-set":
        raise ValueError(f"unknown QP backend {backend!r}; expected one of {', '.join(QP_BACKENDS)}")
    problem = problem_from_shape_model(model, offsets, initial, fixed, gamma)
    return solve_strands(
        problem, BodyDistance(target, band, broad_phase), weights, options, start=start, progress=progress,
        should_stop=should_stop,
    )
