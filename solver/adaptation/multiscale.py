"""The multi-scale solve of Sec. 5 (Eq. 14): guides coupled, then every other strand on its own.

1. Guides (:mod:`.guides`): a few hundred representative strands.
2. Coarse level: Eq. 1 on the guides only, kNN among particles of other guides, solved by
   the coupled solver of :mod:`.solve` (:func:`~.solve.solve_hairstyle`).
3. Fine level (Eq. 14): every other ("normal") particle takes its kNN from guide particles
   only; with the guides adapted, these neighbours are constants and all normal strands
   are independent (:mod:`.active_set`; compiled per-strand kernels, :mod:`.fine_solve`).
   They are solved in chunks of whole strands, so memory stays bounded, in this process on
   numba's threads, or optionally in worker processes (measured slower at 10^5 on two cores,
   and each process holds ~0.5 GB: bench/fine_stage.py).

Convention: particles ``(N, 3) float64`` in meters, CSR strands
(:mod:`hairport.solver.model.hair`); guide ids are strand indices into the full hairstyle.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field, replace
from multiprocessing import get_context

import numpy as np
import scipy.sparse as sp

from hairport.solver.adaptation.fine.fine_chunks import FineInputs, FineSource
from hairport.solver.adaptation.loop.options import ENGINE_COMPILED, SOLVE_STAGE, Cancelled, SolveOptions, SolveReport
from hairport.solver.adaptation.problem.constraints import BodyDistance
from hairport.solver.adaptation.problem.energies import EnergyWeights, ShapeModel, source_directions
from hairport.solver.adaptation.problem.strand_problem import StrandProblem
from hairport.solver.adaptation.solve import solve_hairstyle, solve_strands
from hairport.solver.adaptation.source.guides import select_guides
from hairport.solver.adaptation.source.neighbours import (
    Neighbours,
    knn_other_strands,
    knn_shaped_strands,
    laplacian_operator,
    neighbour_average,
    neighbour_reach,
)
from hairport.solver.jit import set_threads, threads
from hairport.solver.mesh.distance_grid import DistanceGrid
from hairport.solver.mesh.polyline import rest_lengths
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.hair import Hair, particle_indices
from hairport.solver.model.progress import ProgressFn, rescaled

#: particles per fine-level chunk: bounds the fine solve's working memory, measured at 10^5
#: particles (tracemalloc's peak over a chunk's solve): ~470 B a chunk particle for the compiled
#: loop, ~280 of them the distance query's temporaries on a whole-chunk batch (1.6 kB for the
#: numpy reference)
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
    # collapsed strands are no one's neighbours (flagged guides may hold some), isolated strands have none
    reach = neighbour_reach(hair)
    guide_neighbours = knn_shaped_strands(guide_hair, k, reach=reach)
    is_guide = np.isin(np.arange(hair.n_strands), guides)
    is_guide_particle = np.repeat(is_guide, hair.counts)
    normal = np.flatnonzero(~is_guide_particle)
    pool = np.repeat(is_guide & ~hair.collapsed, hair.counts)
    fine_neighbours = knn_other_strands(hair.points, hair.strand_of, k, candidates=pool, queries=normal, reach=reach)
    return MultiscaleModel(guides, guide_neighbours, fine_neighbours)


def coarse_shape_model(hair: Hair, model: MultiscaleModel) -> ShapeModel:
    """Eq. 7/10 operators of the guide hairstyle."""
    guide_hair = hair.subset(model.guides)
    n = guide_hair.n_particles
    K = laplacian_operator(model.guide_neighbours, np.arange(n), n)
    return ShapeModel.build(guide_hair.points, guide_hair.segments, K)


def fine_source(hair: Hair, model: MultiscaleModel) -> FineSource:
    """The fine problem's source-only arrays."""
    strands = np.flatnonzero(~model.is_guide(hair.n_strands))
    particles = particle_indices(hair.offsets, strands)
    directions = source_directions(hair.points[np.minimum(particles + 1, hair.n_particles - 1)] - hair.points[particles])
    nb = model.fine_neighbours
    pull_weight = nb.weight.sum(axis=1)
    features = neighbour_average(nb, hair.points)
    np.subtract(pull_weight[:, None] * hair.points[particles], features, out=features)
    return FineSource(strands, particles, directions, pull_weight, features)


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

    def fine_iterations(self) -> dict:
        """How many outer iterations the fine level's strands took, over all chunks: ``strands``, ``p50``,
        ``p90``, ``p99``, ``max`` (iterations) and ``capped`` (strands the iteration cap stopped, counted at the cap)."""
        longest = max((len(f.stopped) for f in self.fine), default=0)
        counts = np.zeros(longest, dtype=np.int64)
        for level in self.fine:
            counts[:len(level.stopped)] += level.stopped
            if level.capped:
                counts[len(level.stopped) - 1] += level.capped
        total = int(counts.sum())
        if total == 0:
            return {"strands": 0, "p50": 0, "p90": 0, "p99": 0, "max": 0, "capped": 0}
        cumulative = np.cumsum(counts)
        share = {name: int(np.searchsorted(cumulative, q * total) + 1) for name, q in
                 (("p50", 0.5), ("p90", 0.9), ("p99", 0.99))}
        return {"strands": total, **share, "max": int(np.flatnonzero(counts)[-1] + 1),
                "capped": int(sum(level.capped for level in self.fine))}


@dataclass(eq=False)
class FineLevel:
    """One multi-scale solve's fine level once its guides are adapted (Eq. 14), for a
    :data:`FineRunner` to solve: here (:func:`solve_here`) or in chunks elsewhere, where
    :func:`.fine_chunks.chunk_problem` rebuilds any run of strands from the artifact, the
    target and :attr:`inputs`.

    Attributes
    ----------
    problem : StrandProblem
        The normal strands (``len(fine.strands)``), uncoupled.
    start : (n, 3) float64
        Their first iterate.
    body : MeshQuery
        The target's collision surface.
    grid : DistanceGrid or None
    weights : EnergyWeights
    options : SolveOptions
    engine : str
    workers : int
        Processes :func:`solve_here` may use.
    chunk_particles : int
        Particles per chunk in this process.
    inputs : FineInputs
        What another process needs to rebuild the problem.
    """

    problem: StrandProblem
    start: np.ndarray
    body: MeshQuery
    grid: DistanceGrid | None
    weights: EnergyWeights
    options: SolveOptions
    engine: str
    workers: int
    chunk_particles: int
    inputs: FineInputs

    @property
    def counts(self) -> np.ndarray:
        """(R,) int64: particles of each normal strand."""
        return np.diff(self.problem.offsets)


#: solves a :class:`FineLevel`: ``(level, progress, should_stop) -> (points (n, 3), one report per chunk,
#: processes used)``
FineRunner = Callable[[FineLevel, "ProgressFn | None", "Callable[[], bool] | None"],
                      tuple[np.ndarray, list[SolveReport], int]]


def solve_here(level: FineLevel, progress: ProgressFn | None = None,
               should_stop: Callable[[], bool] | None = None) -> tuple[np.ndarray, list[SolveReport], int]:
    """The default :data:`FineRunner`: :func:`solve_fine_level` in this process (or its own pool)."""
    return solve_fine_level(level.problem, level.start, level.body, level.weights, level.options, level.grid,
                            level.workers, level.chunk_particles, level.engine, progress, should_stop)


def solve_level_run(level: FineLevel, first: int, stop: int, progress: ProgressFn | None = None,
                    should_stop: Callable[[], bool] | None = None) -> tuple[np.ndarray, SolveReport]:
    """The normal strands ``first .. stop - 1`` of ``level``, in this process: ``points (n, 3)`` and the report
    (what :func:`hairport.solver.distributed.solve_fine_chunk` gives for them in another)."""
    piece, rows = level.problem.strand_run(first, stop)
    return solve_strands(piece, BodyDistance(level.body, CONTACT_BAND, level.grid), level.weights, level.options,
                         start=level.start[rows], progress=progress, should_stop=should_stop, engine=level.engine)


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
    problem, start, query, grid, weights, options, engine, threads = args
    set_threads(threads)
    distance = BodyDistance(query, CONTACT_BAND, grid)
    return solve_strands(problem, distance, weights, options, start=start, engine=engine)


def fine_problem(hair: Hair, model: MultiscaleModel, fine: FineSource, points: np.ndarray, initial: np.ndarray,
                 gamma: np.ndarray | None = None, *, spacing: bool) -> StrandProblem:
    """Eq. 14 over the normal strands, with the guides where ``points`` has them.

    Each normal particle is pulled towards its guide neighbours' weighted mean plus its source
    offset from them (``K`` diagonal: every strand is its own problem).

    Parameters
    ----------
    hair : Hair
    model : MultiscaleModel
    fine : FineSource
    points : (N, 3) float64
        The whole hairstyle; only the guides' rows are read.
    initial : (N, 3) float64
        ``p-hat`` of the whole hairstyle.
    gamma : (N,) float64, optional
        Eq. 21's weights; 1 everywhere when omitted.
    spacing : bool
        Whether the spacing term is on (the rest lengths are then built; 8 bytes a particle, and
        more while they are).

    Returns
    -------
    problem : StrandProblem
        Over ``fine.particles`` (``len(fine.strands)`` strands).
    """
    nb = model.fine_neighbours
    pull_target = neighbour_average(nb, points) + fine.source_features
    counts = hair.counts[fine.strands]
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    fine_initial = initial[fine.particles]
    return StrandProblem(
        offsets, fine.source_directions, fine_initial, sp.diags(fine.pull_weight, format="csr"),
        pull_target, np.ones(len(fine.particles)) if gamma is None else gamma[fine.particles],
        hair.at_root[fine.particles], rest_lengths(hair.points[fine.particles], fine_initial, offsets) if spacing else None,
    )


def solve_fine_level(
    problem: StrandProblem,
    start: np.ndarray,
    target: MeshQuery,
    weights: EnergyWeights = EnergyWeights(),
    options: SolveOptions = SolveOptions(),
    grid: DistanceGrid | None = None,
    workers: int = 1,
    chunk_particles: int = DEFAULT_CHUNK_PARTICLES,
    engine: str = ENGINE_COMPILED,
    progress: ProgressFn | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> tuple[np.ndarray, list[SolveReport], int]:
    """Eq. 14's independent strands, in chunks of whole strands (:func:`chunk_strands`).

    Parameters
    ----------
    problem : StrandProblem
        :func:`fine_problem`.
    start : (n, 3) float64
        First iterate of its particles.
    target : MeshQuery
    weights : EnergyWeights
    options : SolveOptions
    grid : DistanceGrid, optional
        Broad phase of the target's distance.
    workers : int
        1: the chunks one after the other in this process, each on all of numba's threads;
        more: that many processes (each with its share of the threads).
    chunk_particles : int
        Particles per chunk: bounds the working memory.
    engine : str
        :data:`.options.ENGINES`: the compiled loop or its numpy reference.
    progress : ProgressFn, optional
        ``strands: chunk i/n`` after each chunk.
    should_stop : callable() -> bool, optional
        Polled once per outer iteration in this process, after every chunk with workers.

    Returns
    -------
    points : (n, 3) float64
    reports : list of SolveReport
        One per chunk.
    workers : int
        Processes used (1: this one).
    """
    points = np.array(start, dtype=np.float64)
    counts = np.diff(problem.offsets)
    chunks = chunk_strands(counts, chunk_particles)
    workers = max(1, min(workers, len(chunks)))
    reports: list[SolveReport] = []

    def store(number: int, rows: slice, solved: np.ndarray, chunk_report: SolveReport) -> None:
        points[rows] = solved
        reports.append(chunk_report)
        if progress is not None:
            progress(SOLVE_STAGE, (number + 1) / len(chunks), f"strands: chunk {number + 1}/{len(chunks)}")

    # chunks are runs of consecutive strands: their problems are views, not copies
    pieces = [problem.strand_run(int(chunk[0]), int(chunk[-1]) + 1) for chunk in chunks]
    if workers == 1:
        distance = BodyDistance(target, CONTACT_BAND, grid)
        for number, (piece, rows) in enumerate(pieces):
            store(number, rows, *solve_strands(piece, distance, weights, options, start=start[rows],
                                               should_stop=should_stop, engine=engine))
        return points, reports, workers
    # the query pickles without its trees (rebuilt in the worker), with its inside test
    threads_each = max(1, threads() // workers)
    jobs = ((piece, start[rows], target, grid, weights, options, engine, threads_each) for piece, rows in pieces)
    with ProcessPoolExecutor(workers, mp_context=get_context("spawn")) as pool:
        for number, result in enumerate(pool.map(_solve_chunk, jobs)):
            store(number, pieces[number][1], *result)
            if should_stop is not None and should_stop():
                pool.shutdown(cancel_futures=True)
                raise Cancelled("solve cancelled")
    return points, reports, workers


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
    engine: str = ENGINE_COMPILED,
    fine_runner: FineRunner = solve_here,
    coarse_step_tolerance: float | None = None,
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
        Processes for the fine level (1: in this process, on numba's threads).
    chunk_particles : int
        Particles per fine-level chunk.
    grid : DistanceGrid, optional
        Broad phase of the target's distance.
    backend : str
        QP backend of the coarse level (:data:`.solve.QP_BACKENDS`).
    progress : ProgressFn, optional
        The coarse level's iterations as ``guides: ...`` in ``[0, COARSE_PROGRESS_SHARE]``,
        then ``strands: chunk i/n`` up to 1.
    should_stop : callable() -> bool, optional
        Polled once per outer iteration of either level (per chunk when the fine level runs
        in worker processes).
    engine : str
        How the fine level's loop runs (:data:`.options.ENGINES`): compiled kernels, or the
        numpy reference.
    fine_runner : FineRunner
        Solves the fine level once the guides are adapted (:func:`solve_here` by default; a
        service hands its chunks to other workers).
    coarse_step_tolerance : float, optional
        The coarse level's ``step_tolerance`` (m), above ``options.step_tolerance`` (a warm start's: its guides
        start next to their solution, and stop once an iteration moves none of them further than this).

    Returns
    -------
    points : (N, 3) float64
    report : MultiscaleReport
    """
    report = MultiscaleReport(guides=len(model.guides))
    coarse_progress = _labelled(rescaled(progress, 0.0, COARSE_PROGRESS_SHARE), "guides")
    fine_progress = rescaled(progress, COARSE_PROGRESS_SHARE, 1.0)
    gamma = None if gamma is None else np.asarray(gamma, dtype=np.float64)
    first = np.asarray(initial if start is None else start, dtype=np.float64)
    points = first.copy()

    began = time.perf_counter()
    guide_particles = particle_indices(hair.offsets, model.guides)
    guide_roots = hair.at_root[guide_particles]  # the roots and the particles welded to them stay

    guide_offsets = np.concatenate([[0], np.cumsum(hair.counts[model.guides])])
    guide_points, report.coarse = solve_hairstyle(
        coarse, guide_offsets, initial[guide_particles], guide_roots, target, weights,
        options if coarse_step_tolerance is None else replace(
            options, step_tolerance=max(coarse_step_tolerance, options.step_tolerance)),
        gamma=None if gamma is None else gamma[guide_particles], backend=backend, start=first[guide_particles],
        grid=grid, band=CONTACT_BAND,
        progress=coarse_progress, should_stop=should_stop,
    )
    points[guide_particles] = guide_points
    report.coarse_seconds = time.perf_counter() - began

    began = time.perf_counter()
    if len(fine.strands):
        problem = fine_problem(hair, model, fine, points, initial, gamma, spacing=bool(weights.spacing))
        # without a hairline start the first iterate is p-hat itself: one (n, 3) gather, not two
        fine_start = problem.initial if start is None else first[fine.particles]
        level = FineLevel(problem, fine_start, target, grid, weights, options, engine, workers, chunk_particles,
                          FineInputs(guide_points, initial, gamma, None if start is None else first))
        points[fine.particles], report.fine, report.workers = fine_runner(level, fine_progress, should_stop)
        report.chunks = len(report.fine)
    report.fine_seconds = time.perf_counter() - began
    return points, report
