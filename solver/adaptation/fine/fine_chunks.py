"""The fine level (Eq. 14) as chunks of whole strands that any process can solve.

Once the guides are adapted, every normal strand is an independent problem. A process that
holds the artifact (the adaptable hairstyle) and the target needs only :class:`FineInputs`
(the adapted guides and the retarget's own arrays, a few arrays saved to one ``.npz``) to
rebuild the problem of any run of consecutive normal strands (:func:`chunk_problem`), exactly
as the process that solved the coarse level built it: same rows, same arithmetic, so a chunk
solved elsewhere equals the same strands solved in that process, bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from hairport.solver.adaptation.problem.strand_problem import StrandProblem
from hairport.solver.adaptation.source.neighbours import Neighbours, neighbour_average
from hairport.solver.mesh.polyline import rest_lengths
from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import Hair, particle_indices

#: the arrays of a saved :class:`FineInputs` (the optional ones may be absent)
REQUIRED_ARRAYS = ("guide_points", "initial")
OPTIONAL_ARRAYS = ("gamma", "start")


@dataclass(frozen=True, eq=False)
class FineSource:
    """Source-only parts of the fine problem, one row per normal particle.

    Attributes
    ----------
    strands : (R,) int64
        Normal strand ids, ascending.
    particles : (n,) int64
        Their particles, ascending.
    source_directions : (n, 3) float64
    pull_weight : (n,) float64
    source_features : (n, 3) float64
        ``L-bar_i`` of Eq. 14.
    """

    strands: np.ndarray
    particles: np.ndarray
    source_directions: np.ndarray
    pull_weight: np.ndarray
    source_features: np.ndarray


@dataclass(eq=False)
class FineInputs:
    """What a fine-level chunk needs besides the artifact and the target.

    Attributes
    ----------
    guide_points : (G, 3) float64
        The adapted guides' particles, in the order of ``particle_indices(offsets, guides)``.
    initial : (N, 3) float64
        The initial transfer ``p-hat`` of the whole hairstyle (it also fixes the distance
        grid's region).
    gamma : (N,) float64 or None
        Eq. 21's weights after a hairline edit (None: 1 everywhere).
    start : (N, 3) float64 or None
        The first iterate after a hairline edit (None: ``initial``).
    """

    guide_points: np.ndarray
    initial: np.ndarray
    gamma: np.ndarray | None = None
    start: np.ndarray | None = None

    def save(self, path: Path) -> None:
        """Write the arrays to ``path`` (an uncompressed ``.npz``; the caller makes it atomic)."""
        arrays = {name: getattr(self, name) for name in REQUIRED_ARRAYS + OPTIONAL_ARRAYS}
        with open(path, "wb") as handle:
            np.savez(handle, **{name: value for name, value in arrays.items() if value is not None})

    @classmethod
    def load(cls, path: Path, hair: Hair, guides: np.ndarray) -> FineInputs:
        """Read what :meth:`save` wrote, checked against the hairstyle and its guides (strand ids)."""
        guide_particles = int(hair.counts[np.asarray(guides, dtype=np.int64)].sum())
        with np.load(path, allow_pickle=False) as archive:
            found = {name: np.asarray(archive[name], dtype=np.float64) for name in archive.files}
        missing = [name for name in REQUIRED_ARRAYS if name not in found]
        shapes = {"guide_points": (guide_particles, 3), "initial": (hair.n_particles, 3),
                  "gamma": (hair.n_particles,), "start": (hair.n_particles, 3)}
        wrong = [name for name, value in found.items() if name in shapes and value.shape != shapes[name]]
        if missing or wrong:
            raise InputError(f"the fine level's inputs do not fit the hairstyle (missing {missing}, wrong shape "
                             f"{wrong})", str(path.name), "bad_fine_inputs")
        return cls(found["guide_points"], found["initial"], found.get("gamma"), found.get("start"))


def chunk_problem(hair: Hair, guides: np.ndarray, neighbours: Neighbours, fine: FineSource, inputs: FineInputs,
                  first: int, stop: int, *, spacing: bool) -> tuple[StrandProblem, np.ndarray]:
    """The problem of the normal strands ``first .. stop - 1`` (indices into ``fine.strands``) and its
    first iterate: the rows of :func:`.multiscale.fine_problem`'s problem (its :meth:`~.StrandProblem.strand_run`)
    for those strands, computed from those rows only.

    Parameters
    ----------
    hair : Hair
    guides : (G,) int64
        The guide strands (:attr:`.multiscale.MultiscaleModel.guides`).
    neighbours : Neighbours
        The normal particles' guide neighbours (:attr:`.multiscale.MultiscaleModel.fine_neighbours`).
    fine : FineSource
    inputs : FineInputs
    first, stop : int
    spacing : bool
        Whether the spacing term is on (its rest lengths are then built).

    Returns
    -------
    problem : StrandProblem
    start : (n, 3) float64
    """
    counts = hair.counts[fine.strands]
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    rows = slice(int(offsets[first]), int(offsets[stop]))
    particles = fine.particles[rows]
    guide_points = np.zeros((hair.n_particles, 3))  # the fine kNN point at guide particles only
    guide_points[particle_indices(hair.offsets, guides)] = inputs.guide_points
    rows_neighbours = Neighbours(neighbours.index[rows], neighbours.weight[rows])
    pull_target = neighbour_average(rows_neighbours, guide_points) + fine.source_features[rows]
    gamma = np.ones(len(particles)) if inputs.gamma is None else inputs.gamma[particles]
    chunk_offsets = offsets[first:stop + 1] - offsets[first]
    initial = inputs.initial[particles]
    problem = StrandProblem(
        chunk_offsets, fine.source_directions[rows], initial, sp.diags(fine.pull_weight[rows], format="csr"),
        pull_target, gamma, hair.at_root[particles],
        rest_lengths(hair.points[particles], initial, chunk_offsets) if spacing else None,
    )
    start = problem.initial if inputs.start is None else inputs.start[particles]
    return problem, start
