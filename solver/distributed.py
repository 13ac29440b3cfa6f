"""A multi-scale retarget's fine level solved in pieces, in other processes or on other hosts.

Once the guides are adapted (the coarse level), the fine level (Eq. 14) is every other strand, each
independent of the others. :func:`hairport.solver.retarget` hands that level (a :class:`FineLevel`) to
a :data:`FineRunner`: by default :func:`solve_here` (this process, on numba's threads); the worker's
runner splits it into runs of whole strands (:func:`chunk_strands`), saves what another process needs
(:class:`FineInputs`), and each run is solved by :func:`solve_fine_chunk` elsewhere or by
:func:`solve_level_run` here, with the same numbers bit for bit.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hairport.solver.adaptable import AdaptableHairstyle
from hairport.solver.adaptation.fine.fine_chunks import FineInputs, chunk_problem
from hairport.solver.adaptation.loop.options import SOLVE_STAGE, SolveReport
from hairport.solver.adaptation.multiscale import (
    CONTACT_BAND,
    FineLevel,
    FineRunner,
    chunk_strands,
    solve_here,
    solve_level_run,
)
from hairport.solver.adaptation.problem.constraints import BodyDistance
from hairport.solver.adaptation.solve import solve_strands
from hairport.solver.mesh.collision import collision_query
from hairport.solver.mesh.distance_grid import DistanceGrid
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError
from hairport.solver.model.progress import ProgressFn
from hairport.solver.options import RetargetOptions
from hairport.solver.pipeline import grid_region, shape_solve_options

__all__ = ["SOLVE_STAGE", "FineInputs", "FineLevel", "FineRunner", "SolveReport", "chunk_strands", "solve_fine_chunk",
           "solve_here", "solve_level_run"]


def solve_fine_chunk(
    adaptable: AdaptableHairstyle,
    target: Character,
    options: RetargetOptions,
    inputs: FineInputs,
    first: int,
    stop: int,
    progress: ProgressFn | None = None,
    should_stop: Callable[[], bool] | None = None,
    collision_surface: np.ndarray | None = None,
) -> tuple[np.ndarray, SolveReport]:
    """Solve the normal strands ``first .. stop - 1`` of a multi-scale retarget's fine level in this
    process, as :func:`hairport.solver.retarget` with the same ``adaptable``, ``target`` and ``options``
    would have (bit for bit): the chunk a :data:`FineRunner` handed to another process.

    Parameters
    ----------
    target : Character
        The body the hair touches: for a target of another topology the target itself, not its wrap
        (the fine level needs only its collision surface).
    inputs : FineInputs
        The retarget's :attr:`FineLevel.inputs` (its adapted guides).
    first, stop : int
        Indices into the normal strands (the hairstyle's strands that are not guides, in order).
    collision_surface : (F,) bool, optional
        As for :func:`hairport.solver.retarget`.

    Returns
    -------
    points : (n, 3) float64
        The chunk's particles.
    report : SolveReport
    """
    options.validate()
    fine = adaptable.fine_source
    if not 0 <= first < stop <= len(fine.strands):
        raise InputError(f"strands {first}..{stop} are not a run of the {len(fine.strands)} normal strands",
                         code="bad_fine_chunk")
    # only the body the hair touches: the target itself, of the source's topology or wrapped
    body = collision_query(target.vertices, target.faces, target.name, separating=collision_surface)
    grid = DistanceGrid.build(body, region=grid_region(inputs.initial))
    problem, start = chunk_problem(adaptable.hair, adaptable.multiscale.guides, adaptable.multiscale.fine_neighbours,
                                   fine, inputs, first, stop, spacing=bool(options.spacing))
    return solve_strands(problem, BodyDistance(body, CONTACT_BAND, grid), options.energy_weights(),
                         shape_solve_options(options), start=start, progress=progress, should_stop=should_stop)
