"""The multi-scale solve of Sec. 5 (Eq. 14): guides coupled, then every other strand on its own.

1. Guides (:mod:`.guides`): a few hundred representative strands.
2. Coarse level: Eq. 1 on the guides only, kNN among particles of other guides, solved by
   the coupled solver of :mod:`.coupled`.
3. Fine level (Eq. 14): every other ("normal") particle takes its kNN from guide particles
   only; with the guides adapted, these neighbours are constants and all normal strands
   are independent (:mod:`.active_set`). They are solved in chunks of whole strands, so
   memory stays bounded, optionally in parallel processes.

Convention: particles ``(N, 3) float64`` in meters, CSR strands
(:mod:`hairport.solver.model.hair`); guide ids are strand indices into the full hairstyle.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from multiprocessing import get_context

import numpy as np
import scipy.sparse as sp

from hairport.solver.adaptation.active_set import solve_strands
from hairport.solver.adaptation.constraints import BodyDistance
from hairport.solver.adaptation.coupled import solve_hairstyle
from hairport.solver.adaptation.energies import EnergyWeights, ShapeModel, unit_rows
from hairport.solver.adaptation.guides import select_guides
from hairport.solver.adaptation.neighbours import Neighbours, knn_other_strands, laplacian_operator, neighbour_average
from hairport.solver.adaptation.options import SOLVE_STAGE, Cancelled, SolveOptions, SolveReport
from hairport.solver.adaptation.strand_problem import StrandProblem
from hairport.solver.mesh.distance_grid import DistanceGrid
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.hair import Hair, particle_indices
from hairport.solver.model.progress import ProgressFn, rescaled

#: particles per fine-level chunk: bounds the fine solve's working memory (~1 kB per particle)
DEFAULT_CHUNK_PARTICLES = 200_000
#: particles outside the body and farther than this from it (by the distance grid's bound)
#: get no exact closest-point query and no Eq. 13 constraint in an iteration (m); it exceeds
#: every step the line search accepts near the body, and the merit test re-queries moved
#: particles; particles inside are queried at any depth (:class:`.constraints.BodyDistance`)
CONTACT_BAND = 0.02
#: the coarse level reports its progress in [0, this] of the solve's range, the fine level in the rest
COARSE_PROGRESS_SHARE = 0.5


@dataclass(frozen=True, eq=False)
class MultiscaleModel:
    """Source-only data of the multi-scale solve.

    Attributes
    ----------
    guides : (G,) int64
        Guide strand ids, ascending.
    guide_neighbours : Neighbours
        Eq. 8-9 over the guide hairstyle ``hair.subset(guides)``: one row per guide particle,
        indices into that sub-hairstyle.
    fine_neighbours : Neighbours
        Eq. 14: one row per normal particle (ascending particle order), indices into the full
        hairstyle, all of guide particles.
    """

    guides: np.ndarray
    guide_neighbours: Neighbours
    fine_neighbours: Neighbours

    def is_guide(self, n_strands: int) -> np.ndarray:
        """(S,) bool."""
        mask = np.zeros(n_strands, dtype=bool)
        mask[self.guides] = True
        return mask


def build_multiscale_model(hair: Hair, n_guides: int, k: int, seed: int = 0) -> MultiscaleModel:
    """Select guides and find the coarse and fine kNN sets on the source hairstyle."""
    return multiscale_model(hair, select_guides(hair, n_guides, seed=seed), k)


def multiscale_model(hair: Hair, guides: np.ndarray, k: int) -> MultiscaleModel:
    """The coarse and fine kNN sets of the source hairstyle with these guides ``(G,) int64``."""
    guide_hair = hair.subset(guides)
    guide_neighbours = knn_other_strands(guide_hair.points, guide_hair.strand_of, k)
    is_guide_particle = np.repeat(np.isin(np.arange(hair.n_strands), guides), hair.counts)
    normal = np.flatnonzero(~is_guide_particle)
    fine_neighbours = knn_other_strands(hair.points, hair.strand_of, k, candidates=is_guide_particle, queries=normal)
    return MultiscaleModel(guides, guide_neighbours, fine_neighbours)


def coarse_shape_model(hair: Hair, model: MultiscaleModel) -> ShapeModel:
    """Eq. 7/10 operators of the guide hairstyle."""
    guide_hair = hair.subset(model.guides)
    n = guide_hair.n_particles
    K = laplacian_operator(model.guide_neighbours, np.arange(n), n)
    return ShapeModel.build(guide_hair.points, guide_hair.segments, K)


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


def fine_source(hair: Hair, model: MultiscaleModel) -> FineSource:
    """The fine problem's source-only arrays."""
    strands = np.flatnonzero(~model.is_guide(hair.n_strands))
    particles = particle_indices(hair.offsets, strands)
    _, unit = unit_rows(hair.points[np.minimum(particles + 1, hair.n_particles - 1)] - hair.points[particles])
    nb = model.fine_neighbours
    pull_weight = nb.weight.sum(axis=1)
    features = neighbour_average(nb, hair.points)
    np.subtract(pull_weight[:, None] * hair.points[particles], features, out=features)
    return FineSource(strands, particles, unit, pull_weight, features)


@dataclass
class MultiscaleReport:
    """What the two levels did: the guides' coupled solve and one active-set report per fine-level chunk."""

    guides: int = 0
    coarse: SolveReport | None = None
    fine: list[SolveReport] = field(default_factory=list)
    coarse_seconds: float = 0.0
    fine_seconds: float = 0.0
    chunks: int = 0
    workers: int = 1

    @property
    def converged(self) -> bool:
        return (self.coarse is None or self.coarse.converged) and all(f.converged for f in self.fine)

    @property
    def iterations(self) -> int:
        """Outer iterations of the longest-running level."""
        return max([self.coarse.iterations if self.coarse else 0] + [f.iterations for f in self.fine])

    @property
    def pushed_out(self) -> int:
        return (self.coarse.pushed_out if self.coarse else 0) + sum(f.pushed_out for f in self.fine)


def default_workers() -> int:
    """Processes for the fine level: the CPUs this process may use."""
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1)


def chunk_strands(counts: np.ndarray, chunk_particles: int) -> list[np.ndarray]:
    """Split strands with ``counts (R,)`` particles into consecutive runs of at most ``chunk_particles`` particles
    (a strand longer than that is a chunk of its own)."""
    if len(counts) == 0:
        return []
    ends = np.cumsum(counts)
    bounds = [0]
    while bounds[-1] < len(counts):
        start_total = ends[bounds[-1] - 1] if bounds[-1] else 0
        stop = int(np.searchsorted(ends, start_total + chunk_particles, side="right"))
        bounds.append(max(stop, bounds[-1] + 1))
    return [np.arange(a, b) for a, b in zip(bounds[:-1], bounds[1:])]


def _labelled(progress: ProgressFn, label: str) -> ProgressFn:
    """``progress`` with every message prefixed by ``label: ``."""

    def report(stage: str, fraction: float, message: str) -> None:
        progress(stage, fraction, f"{label}: {message}")

    return report


def _solve_chunk(args) -> tuple[np.ndarray, SolveReport]:
    problem, start, query, grid, weights, options = args
    distance = BodyDistance(query, CONTACT_BAND, grid)
    return solve_strands(problem, distance, weights, options, start=start)


def solve_multiscale(
    hair: Hair,
    model: MultiscaleModel,
    coarse: ShapeModel,
    fine: FineSource,
    initial: np.ndarray,
    target: MeshQuery,
    weights: EnergyWeights = EnergyWeights(),
    options: SolveOptions = SolveOptions(),
    gamma: np.ndarray | None = None,
    start: np.ndarray | None = None,
    workers: int = 1,
    chunk_particles: int = DEFAULT_CHUNK_PARTICLES,
    grid: DistanceGrid | None = None,
    backend: str = "active-set",
    progress: ProgressFn | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> tuple[np.ndarray, MultiscaleReport]:
    """Eq. 1 by the two levels of Sec. 5.

    Parameters
    ----------
    hair : Hair
        The source hairstyle (layout, roots).
    model : MultiscaleModel
    coarse : ShapeModel
        :func:`coarse_shape_model`.
    fine : FineSource
        :func:`fine_source`.
    initial : (N, 3) float64
        ``p-hat`` of the whole hairstyle.
    target : MeshQuery
    weights : EnergyWeights
    options : SolveOptions
    gamma : (N,) float64, optional
        Eq. 21's weights.
    start : (N, 3) float64, optional
        First iterate (``initial`` by default); the roots stay where it puts them (Eq. 12,
        relocated roots after a hairline edit).
    workers : int
        Processes for the fine level (1: in this process).
    chunk_particles : int
        Particles per fine-level chunk.
    grid : DistanceGrid, optional
        Broad phase of the target's distance.
    backend : str
        QP backend of the coarse level (:data:`.coupled.QP_BACKENDS`).
    progress : ProgressFn, optional
        The coarse level's iterations as ``guides: ...`` in ``[0, COARSE_PROGRESS_SHARE]``,
        then ``strands: chunk i/n`` up to 1.
    should_stop : callable() -> bool, optional
        Polled by the coarse level once per iteration, by the fine level per chunk.

    Returns
    -------
    points : (N, 3) float64
    report : MultiscaleReport
    """
    report = MultiscaleReport(guides=len(model.guides))
    coarse_progress = _labelled(rescaled(progress, 0.0, COARSE_PROGRESS_SHARE), "guides")
    fine_progress = rescaled(progress, COARSE_PROGRESS_SHARE, 1.0)
    gamma_all = np.ones(hair.n_particles) if gamma is None else np.asarray(gamma, dtype=np.float64)
    first = np.asarray(initial if start is None else start, dtype=np.float64)
    points = first.copy()

    began = time.perf_counter()
    guide_particles = particle_indices(hair.offsets, model.guides)
    guide_roots = np.zeros(len(guide_particles), dtype=bool)
    guide_roots[np.concatenate([[0], np.cumsum(hair.counts[model.guides])[:-1]])] = True

    guide_offsets = np.concatenate([[0], np.cumsum(hair.counts[model.guides])])
    guide_points, report.coarse = solve_hairstyle(
        coarse, guide_offsets, initial[guide_particles], guide_roots, target, weights, options,
        gamma=gamma_all[guide_particles], backend=backend, start=first[guide_particles],
        grid=grid, band=CONTACT_BAND,
        progress=coarse_progress, should_stop=should_stop,
    )
    points[guide_particles] = guide_points
    report.coarse_seconds = time.perf_counter() - began

    began = time.perf_counter()
    if len(fine.strands):
        nb = model.fine_neighbours
        pull_target = neighbour_average(nb, points) + fine.source_features
        is_root = hair.is_root[fine.particles]
        counts = hair.counts[fine.strands]
        offsets = np.concatenate([[0], np.cumsum(counts)])
        problem = StrandProblem(
            offsets, fine.source_directions, initial[fine.particles], sp.diags(fine.pull_weight, format="csr"),
            pull_target, gamma_all[fine.particles], is_root,
        )
        chunks = chunk_strands(counts, chunk_particles)
        report.chunks = len(chunks)
        report.workers = max(1, min(workers, len(chunks)))
        indices: list[np.ndarray] = []

        fine_start = first[fine.particles]

        def pieces():
            # one chunk's copy at a time in this process (the pool keeps its own queue)
            for chunk in chunks:
                piece, index = problem.subset(chunk)
                indices.append(index)
                yield piece, fine_start[index]

        def store(number: int, solved: np.ndarray, fine_report: SolveReport) -> None:
            points[fine.particles[indices[number]]] = solved
            report.fine.append(fine_report)
            fine_progress(SOLVE_STAGE, (number + 1) / len(chunks), f"strands: chunk {number + 1}/{len(chunks)}")

        if report.workers == 1:
            distance = BodyDistance(target, CONTACT_BAND, grid)
            for number, (piece, piece_start) in enumerate(pieces()):
                store(number, *solve_strands(piece, distance, weights, options, start=piece_start,
                                             should_stop=should_stop))
        else:
            # the query pickles without its trees (rebuilt in the worker), with its inside test
            jobs = ((piece, piece_start, target, grid, weights, options)
                    for piece, piece_start in pieces())
            with ProcessPoolExecutor(report.workers, mp_context=get_context("spawn")) as pool:
                for number, result in enumerate(pool.map(_solve_chunk, jobs)):
                    store(number, *result)
                    if should_stop is not None and should_stop():
                        pool.shutdown(cancel_futures=True)
                        raise Cancelled("solve cancelled")
    report.fine_seconds = time.perf_counter() - began
    return points, report
