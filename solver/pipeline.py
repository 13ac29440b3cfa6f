"""The one entry point the CLI, the worker and the benchmarks call.

``preprocess(source, hair)`` computes everything that depends on the source only (the
"adaptable hairstyle"); ``retarget(adaptable, target)`` adapts it to one target: initial
transfer (Eq. 2-6), then shape adaptation (Eq. 1) or a baseline, then the final penetration
check for the methods that claim a penetration-free result (the solvers, baselines with
``+pushout``: :func:`~hairport.solver.mesh.penetration.resolve_penetration`) and, for the
solvers, of their segments (:func:`~hairport.solver.mesh.penetration.resolve_crossings`), then metrics.
Collisions (Eq. 13, push-outs, the check, the penetration metrics) are against the target's
collision surface (:func:`~hairport.solver.mesh.collision.collision_query`); anchoring and the
roots' metrics against its whole mesh.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, replace

import numpy as np

from hairport.solver.adaptable import AdaptableHairstyle
from hairport.solver.adaptation.loop.options import SolveOptions, SolveReport
from hairport.solver.adaptation.multiscale import (
    FineRunner,
    MultiscaleReport,
    multiscale_model,
    solve_here,
    solve_multiscale,
)
from hairport.solver.adaptation.problem.energies import EnergyWeights
from hairport.solver.adaptation.solve import solve_hairstyle
from hairport.solver.adaptation.source.guide_flags import flagged_guides
from hairport.solver.adaptation.source.guides import select_guides
from hairport.solver.baselines import parse_method, retarget_baseline
from hairport.solver.body.target import prepare_target
from hairport.solver.hairline.edit import HairlineEdit
from hairport.solver.hairline.relocation import Relocation, relocate_roots
from hairport.solver.hairline.weights import adaptive_weights
from hairport.solver.mesh.collision import collision_query
from hairport.solver.mesh.distance_grid import DistanceGrid
from hairport.solver.mesh.penetration import distances_after, resolve_crossings, resolve_penetration
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.mesh.segment_crossing import crossing_segments
from hairport.solver.metrics import hairstyle_metrics, particle_distances, penetration, penetration_stats
from hairport.solver.model.character import Character
from hairport.solver.model.degenerate import require_no_stray_strands
from hairport.solver.model.frame import InputFrame
from hairport.solver.model.hair import DEGENERATE_SEGMENT_M, Hair, require_hair
from hairport.solver.model.progress import ProgressFn, no_progress, rescaled
from hairport.solver.options import OPTION_RANGES, SOLVER_METHODS, PreprocessOptions, RetargetOptions
from hairport.solver.transfer.anchors import compute_anchors, place_anchors, resolve_anchoring, root_targets
from hairport.solver.transfer.carry import carry_shapes
from hairport.solver.transfer.smoothing import SMOOTHING_EPS, smooth_strands
from hairport.solver.wrapping import WrappedTarget, needs_wrap, onto_body, require_a_wrap_for, wrap_target

#: the multi-scale solve's distance grid covers the initial transfer's box grown by this (m);
#: particles that leave it are still queried exactly, only without the grid's shortcut
GRID_REGION_MARGIN = 0.05
#: a warm frame's coarse level (multi-scale) stops once an iteration moves no guide particle further than this (m):
#: its guides start next to their solution, where the coupled loop's steps shrink to a millimetre in two iterations
#: and then crawl. Measured on a 24-step body sweep at 10^5 particles (docs/performance.md, "Sequences"): two
#: iterations in most frames, against 5-8 to the default tolerance; three or four where a guide slides over the
#: body, which a fixed cap of two stopped short of (a 23 mm jump of one strand's particles)
WARM_COARSE_STEP_M = 2e-3
#: a warm frame's distance grid is exact only within this (m) of its first iterate (the previous frame's result
#: carried), where its particles stay (:meth:`~hairport.solver.mesh.distance_grid.DistanceGrid.build`'s ``near``)
WARM_GRID_REACH = 0.01


@dataclass(eq=False)
class RetargetResult:
    """A retargeted hairstyle with what was measured on the way (``relocation``: the hairline
    edit's relocated roots and deformed scalp, when one was asked for)."""

    hair: Hair
    initial: Hair
    metrics: dict
    timings: dict
    solve: SolveReport | MultiscaleReport | None = None
    relocation: Relocation | None = None
    #: (N,) bool: the particles inside the target body (the metrics' penetration test)
    inside: np.ndarray | None = None
    #: the wrap of the source body onto a target of another topology (None: the target's own topology)
    wrapped: WrappedTarget | None = None
    #: (N,) bool: the particles that start a segment passing through the target body between two particles
    #: outside it (:mod:`~hairport.solver.mesh.segment_crossing`)
    crossing: np.ndarray | None = None
    #: (N, 3) the first iterate this target gives without an earlier frame: the initial transfer, or the hairline
    #: edit's start (what :class:`PreviousFrame` measures the body's motion against)
    base: np.ndarray | None = None
    #: the target's query and its collision query, kept (``retarget(keep_queries=True)``) for a sequence's next frame
    #: to move instead of building; the sequence lets go of them once that frame has them
    queries: tuple[MeshQuery, MeshQuery] | None = None

    def report(self) -> dict:
        """JSON-ready report: metrics, per-stage timings (s), solver trace."""
        out = {"metrics": self.metrics, "timings_s": self.timings}
        if self.solve is not None:
            out["solver"] = asdict(self.solve)
        return out

    def as_previous(self) -> PreviousFrame:
        """What the next frame of a sequence starts from."""
        return PreviousFrame(self.hair.points, self.base, self.queries)


@dataclass(frozen=True, eq=False)
class PreviousFrame:
    """The previous frame of a sequence, for a warm start.

    Attributes
    ----------
    points : (N, 3) float64
        Its result.
    base : (N, 3) float64
        Its :attr:`RetargetResult.base`.
    queries : (MeshQuery, MeshQuery) or None
        Its :attr:`RetargetResult.queries`: a frame of the same mesh moves them (:func:`target_bodies`).
    """

    points: np.ndarray
    base: np.ndarray
    queries: tuple[MeshQuery, MeshQuery] | None = None

    def carried(self, base: np.ndarray) -> np.ndarray:
        """The previous result moved as the body moved: ``points + (base - self.base)`` (``base : (N, 3)``, this
        frame's); a root lands on this frame's root, as both bases hold their frame's roots."""
        return self.points + (base - self.base)


def warm_start(initial: np.ndarray, start: np.ndarray | None, weights: EnergyWeights, previous: PreviousFrame | None,
               temporal: float) -> tuple[np.ndarray | None, np.ndarray, EnergyWeights]:
    """The solve's first iterate, Eq. 11's anchor and the weights: ``(start, initial, weights)`` as they are without a
    previous frame, else the previous result carried to this frame, the anchor with the temporal term joined
    (:func:`temporal_anchor`) and ``beta`` raised by it.

    Parameters
    ----------
    initial : (N, 3) float64
        The initial transfer.
    start : (N, 3) float64 or None
        The first iterate without a previous frame (a hairline edit's).
    """
    if previous is None:
        return start, initial, weights
    carried = previous.carried(initial if start is None else start)
    anchor, beta = temporal_anchor(initial, carried, weights.beta, temporal)
    return carried, anchor, replace(weights, beta=beta)


def temporal_anchor(initial: np.ndarray, carried: np.ndarray, beta: float, temporal: float) -> tuple[np.ndarray, float]:
    """Eq. 11 with a second anchor: ``beta || p - p-hat ||^2 + temporal || p - carried ||^2`` equals, up to a constant,
    ``(beta + temporal) || p - anchor ||^2`` with ``anchor = (beta p-hat + temporal carried) / (beta + temporal)``.

    Parameters
    ----------
    initial, carried : (N, 3) float64
    beta, temporal : float
        Non-negative weights (per m^2).

    Returns
    -------
    anchor : (N, 3) float64
    weight : float
        ``beta + temporal``, Eq. 11's weight with the anchor.
    """
    weight = beta + temporal
    if temporal == 0.0 or weight == 0.0:
        return initial, beta
    return initial + (temporal / weight) * (carried - initial), weight


@contextmanager
def timed(timings: dict[str, float], stage: str) -> Iterator[None]:
    """Record in ``timings[stage]`` the seconds the block took (when it ends without an error)."""
    began = time.perf_counter()
    yield
    timings[stage] = time.perf_counter() - began


def preprocess(
    source: Character,
    hair: Hair,
    options: PreprocessOptions = PreprocessOptions(),
    progress: ProgressFn | None = None,
    *,
    frame: InputFrame | None = None,
    input_report: dict | None = None,
) -> AdaptableHairstyle:
    """Compute the adaptable hairstyle: anchors (Eq. 2) and kNN sets/weights (Eq. 8-9).

    Parameters
    ----------
    source : Character
        The source character in hairport's frame; rigged (skeleton and skin weights) for
        ``options.anchoring="bones"``, anchored by its surface when it has no rig.
    hair : Hair
        The hairstyle made for ``source``.
    frame, input_report : optional
        The groom file's frame and the report's ``input`` section, from
        :func:`~hairport.solver.inputs.canonical_source`; kept with the result.
    """
    progress = progress or no_progress
    options.validate()
    require_hair(hair.points, hair.offsets, "hair", DEGENERATE_SEGMENT_M)  # never an artifact without hair
    require_no_stray_strands(hair.points, hair.offsets, "hair")  # (model.degenerate: the kinds and why)
    options = replace(options, anchoring=resolve_anchoring(options.anchoring, source))
    timings: dict[str, float] = {}
    with timed(timings, "anchors"):
        progress("anchors", 0.0, f"anchoring particles by the {options.anchoring}")
        query = MeshQuery(source.vertices, source.faces)
        anchors = compute_anchors(source, hair.points, hair.is_root, query, options.sigma, options.anchoring)
    with timed(timings, "guides"):
        progress("guides", 0.5, "selecting guides")
        if options.guides_from is None:
            guides = select_guides(hair, options.guides, seed=options.guide_seed)
        else:
            guides = flagged_guides(hair, options.guides_from, OPTION_RANGES["guides"].maximum)
            options = replace(options, guides=len(guides))
    with timed(timings, "neighbours"):
        progress("neighbours", 0.7, "finding the inter-strand neighbours")
        multiscale = multiscale_model(hair, guides, options.k)
    progress("preprocess", 1.0, "done")
    bone_names = source.skeleton.names if source.skeleton is not None else ()
    return AdaptableHairstyle(source, hair, anchors, multiscale, options, bone_names, timings,
                              frame or InputFrame(), dict(input_report or {}))


def initial_transfer(
    adaptable: AdaptableHairstyle,
    target: Character,
    eps_s: float = SMOOTHING_EPS,
    query: MeshQuery | None = None,
    carry: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 3, Eq. 4-6, then the shape carry over ``carry`` m (beyond the paper; 0: none,
    :mod:`~hairport.solver.transfer.carry`); the particles welded to a root
    (:attr:`~hairport.solver.model.hair.Hair.at_root`) end on it.

    Returns
    -------
    initial : (N, 3) float64
        ``p-hat``.
    unsmooth : (N,) bool
        Particles that were smoothed.
    """
    hair = adaptable.hair
    anchored = place_anchors(adaptable.anchors, target, query)
    smoothed, unsmooth = smooth_strands(anchored, hair.points, hair.offsets, eps_s, laplacian=adaptable.strand_laplacian)
    # every array here is this call's own: the particles at a root are placed in place
    return hair.place_at_roots(carry_shapes(smoothed, hair.points, hair.offsets, hair.at_root, carry)), unsmooth


def retarget(
    adaptable: AdaptableHairstyle,
    target: Character,
    options: RetargetOptions = RetargetOptions(),
    progress: ProgressFn | None = None,
    should_stop: Callable[[], bool] | None = None,
    target_input: dict | None = None,
    fine_runner: FineRunner = solve_here,
    collision_surface: np.ndarray | None = None,
    wrapped: WrappedTarget | None = None,
    previous: PreviousFrame | None = None,
    temporal: float = 0.0,
    keep_queries: bool = False,
) -> RetargetResult:
    """Adapt the hairstyle to ``target``.

    Parameters
    ----------
    adaptable : AdaptableHairstyle
        From :func:`preprocess`.
    target : Character
        Canonical frame. Of the source's topology (a skeleton is transferred when it has none), or of
        another, onto which the source body is wrapped first (``options.wrap``, :mod:`~hairport.solver.wrapping`).
    options : RetargetOptions
    progress : callable(stage, fraction, message), optional
    should_stop : callable() -> bool, optional
        Polled between solver iterations (cancellation).
    target_input : dict, optional
        What :func:`~hairport.solver.inputs.canonical_target` found; with the hairstyle's own
        it makes the metrics' ``input`` section.
    fine_runner : FineRunner
        Solves the multi-scale fine level (in this process by default;
        :func:`hairport.solver.distributed.solve_fine_chunk` solves a run of its strands in another).
    collision_surface : (F,) bool, optional
        The target's :func:`~hairport.solver.mesh.collision.collision_faces`, kept from an earlier
        build (a per-target cache); built here when omitted.
    wrapped : WrappedTarget, optional
        The wrap of this source onto this target from an earlier retarget (:attr:`RetargetResult.wrapped`,
        a cache keyed by :func:`~hairport.solver.wrapping.wrap_key`); wrapped here when needed and omitted.
    previous : PreviousFrame, optional
        The previous frame of a sequence (:mod:`~hairport.solver.sequence`): the solvers start from its result moved
        as the body moved, not from this target's initial transfer.
    temporal : float
        With ``previous``: the weight (per m^2, as Eq. 11's ``beta``) of a pull toward that moved result
        (:func:`temporal_anchor`; :class:`~hairport.solver.options.SequenceOptions`).
    keep_queries : bool
        Keep the target's queries in :attr:`RetargetResult.queries` (a sequence's frame, for the next one); a
        single retarget lets them go with its stack (~15 MB each on the MakeHuman body).
    """
    options.validate()
    progress = progress or no_progress
    hair = adaptable.hair
    timings: dict[str, float] = {}
    bodies = target_bodies(adaptable, target, options, timings, progress, collision_surface, wrapped,
                           previous.queries if previous is not None else None)
    target, contact, target_query, contact_query, body, wrapped = bodies
    with timed(timings, "initial_transfer"):
        progress("initial_transfer", 0.05, "initial transfer")
        initial, unsmooth = initial_transfer(adaptable, target, options.eps_s, target_query, options.carry)

    roots = root_targets(target, adaptable.anchors.face[hair.roots], adaptable.anchors.barycentric[hair.roots])
    if wrapped is not None:
        initial, roots = onto_body(hair, initial, roots, contact_query)
    start = gamma = relocation = None
    if options.hairline is not None:
        progress("hairline", 0.07, f"relocating the roots for the hairline edit {options.hairline.describe()}")
        relocation, start, gamma = relocate_hairline(adaptable, target, initial, roots, options.hairline)
        if wrapped is not None:
            start, relocation.roots = onto_body(hair, start, relocation.roots, contact_query)
        roots = relocation.roots
        timings["hairline"] = relocation.report["seconds"]

    base = initial if start is None else start
    weights = options.energy_weights()
    if options.method in SOLVER_METHODS:
        claims_outside = True
        start, anchor, solve_weights = warm_start(initial, start, weights, previous, temporal)
        with timed(timings, "solve"):
            points, solve_report = adapt_shape(adaptable, body, anchor, options, solve_weights, timings, gamma,
                                               start, progress, should_stop, fine_runner, warm=previous is not None)
    else:
        solve_report = None
        with timed(timings, "baseline"):
            progress("baseline", 0.1, f"baseline {options.method}")
            base, claims_outside = parse_method(options.method)
            # on a wrap, the baseline places the hair on the wrapped shape; the penetration check below then pushes
            # it out of the target itself
            points = retarget_baseline(base, adaptable.source, target, hair, pushout=claims_outside and wrapped is None,
                                       clearance=options.eps_c, target_query=body if wrapped is None else None).points
            if wrapped is not None:
                points, _ = onto_body(hair, points, points[hair.roots], contact_query)
            # a collapsed strand stays on its root, as with the solvers (on a copy: a baseline may share arrays)
            points = hair.place_at_roots(np.array(points, dtype=np.float64))

    resolved = segments_resolved = body_distance = crossings = None
    if claims_outside:
        with timed(timings, "penetration_check"):
            progress("penetration_check", 0.94, "checking that no particle or segment is inside the body")
            points, resolved, segments_resolved, body_distance, crossings = final_check(points, hair, body, options,
                                                                                        contact.name)

    with timed(timings, "metrics"):
        progress("metrics", 0.95, "measuring")
        body_distance = body_distance or penetration(points, hair.at_root, body, options.eps_c)
        inside = np.zeros(hair.n_particles, dtype=bool)
        inside[~hair.at_root] = body_distance["distance"] < 0.0
        crossings = crossings or crossing_segments(points, hair.segments, hair.at_root, body,
                                                   particle_distances(body_distance, hair.at_root))
        metrics = hairstyle_metrics(points, hair, initial, roots, adaptable.neighbours, contact_query, options.eps_c,
                                    weights, body=body, penetration_stats=body_distance, crossings=crossings)
        metrics.update(method=options.method, smoothed_particles=int(unsmooth.sum()),
                       anchoring=adaptable.options.anchoring, fallback_anchors=int(adaptable.anchors.fallback.sum()))
        metrics.update({name: value for name, value in (
            ("penetration_resolved", resolved), ("segments_resolved", segments_resolved),
            ("hairline", relocation and relocation.report), ("wrap", wrapped and wrapped.report)) if value is not None})
        if adaptable.input_report or target_input:
            metrics["input"] = {**adaptable.input_report, **({"target": target_input} if target_input else {})}
    progress("done", 1.0, "done")
    return RetargetResult(
        hair.with_points(points), hair.with_points(initial), metrics, timings, solve_report, relocation, inside,
        wrapped, crossings.starts(hair.segments, hair.n_particles), base, (target_query, body) if keep_queries else None,
    )


def final_check(points: np.ndarray, hair: Hair, body: MeshQuery, options: RetargetOptions, name: str) -> tuple:
    """The final check of a method that claims a penetration-free result: no particle inside the body
    (:func:`~hairport.solver.mesh.penetration.resolve_penetration`) and, for the solvers, no segment through it
    (:func:`~hairport.solver.mesh.penetration.resolve_crossings`); a baseline's push-out promises its particles
    (its segments are counted in the metrics).

    Returns
    -------
    points : (N, 3) float64
    resolved : dict
        The particles' check.
    segments_resolved : dict or None
        The segments' check (None for a baseline).
    body_distance : dict
        :func:`~hairport.solver.metrics.penetration` at ``points``.
    crossings : SegmentCrossings or None
        The segments through the body at ``points`` (none; None for a baseline, whose segments are not checked).
    """
    # one query of every particle serves both checks and the metrics: after it, only moved particles are queried
    distance = particle_distances(penetration(points, hair.at_root, body, options.eps_c), hair.at_root)
    pushed, resolved = resolve_penetration(points, hair.at_root, body, options.eps_c, name, distance,
                                           hair.short_segments)
    if resolved["particles"]:
        distance, _ = distances_after(points, pushed, distance, hair.at_root, body)
    points, segments_resolved, crossings = pushed, None, None
    if options.method in SOLVER_METHODS:
        points, segments_resolved, crossings, distance = resolve_crossings(
            points, hair.segments, hair.at_root, body, options.eps_c, hair.offsets, name, distance,
            hair.short_segments)
    return points, resolved, segments_resolved, penetration_stats(distance[~hair.at_root], options.eps_c), crossings


def target_bodies(adaptable: AdaptableHairstyle, target: Character, options: RetargetOptions,
                  timings: dict[str, float], progress: ProgressFn, collision_surface: np.ndarray | None,
                  wrapped: WrappedTarget | None, moved_from: tuple[MeshQuery, MeshQuery] | None = None) -> tuple:
    """The two meshes a retarget uses: the one of the source's topology that gives the correspondence (the target
    itself, or the source body wrapped onto it) and the one the hair touches (the target itself). ``moved_from``:
    the shape's query and the collision query of an earlier frame of this mesh (:attr:`RetargetResult.queries`),
    moved to this frame rather than built (:meth:`~hairport.solver.mesh.query.MeshQuery.moved`).

    Returns
    -------
    shape : Character
        Prepared (:func:`~hairport.solver.body.target.prepare_target`).
    contact : Character
    shape_query, contact_query : MeshQuery
    body : MeshQuery
        The contact's collision surface.
    wrapped : WrappedTarget or None
    """
    contact = target
    if needs_wrap(adaptable.source, target, options.wrap):
        if wrapped is None:
            with timed(timings, "wrap"):
                progress("wrap", 0.0, f"wrapping the source body onto the target ({target.n_vertices:,} vertices)")
                wrapped = wrap_target(adaptable, target, landmarks=options.landmarks)
        target = wrapped.shape
    else:
        require_a_wrap_for(options.landmarks, options.wrap)
        wrapped = None
    with timed(timings, "prepare"):
        progress("prepare", 0.02, "checking the target")
        target = prepare_target(adaptable, target)
        shape_before, body_before = moved_from if moved_from is not None else (None, None)
        target_query = shape_query(target, shape_before)
        body = collision_query(contact.vertices, contact.faces, contact.name, separating=collision_surface,
                               moved_from=body_before)
        contact_query = target_query if wrapped is None else MeshQuery(contact.vertices, contact.faces)
    return target, contact, target_query, contact_query, body, wrapped


def shape_query(shape: Character, before: MeshQuery | None) -> MeshQuery:
    """The query of ``shape``: ``before`` moved to its vertices when that is a plain query of its mesh, else new."""
    if before is not None and before.inside_test is None and before.vertices.shape == shape.vertices.shape \
            and np.array_equal(before.faces, shape.faces):
        return before.moved(shape.vertices)
    return MeshQuery(shape.vertices, shape.faces)


def adapt_shape(
    adaptable: AdaptableHairstyle,
    target_query: MeshQuery,
    initial: np.ndarray,
    options: RetargetOptions,
    weights: EnergyWeights,
    timings: dict[str, float],
    gamma: np.ndarray | None = None,
    start: np.ndarray | None = None,
    progress: ProgressFn = no_progress,
    should_stop: Callable[[], bool] | None = None,
    fine_runner: FineRunner = solve_here,
    warm: bool = False,
) -> tuple[np.ndarray, SolveReport | MultiscaleReport]:
    """Eq. 1 under Eq. 12-13, by the multi-scale solve (Sec. 5) or over all strands coupled.

    Parameters
    ----------
    initial : (N, 3) float64
        The initial transfer ``p-hat``.
    timings : dict
        Receives the distance grid's and the two levels' seconds (multi-scale).
    gamma : (N,) float64, optional
        Eq. 20's weights after a hairline edit.
    start : (N, 3) float64, optional
        The first iterate (``initial`` by default).
    warm : bool
        ``start`` is a sequence's previous frame carried to this one: the multi-scale coarse level stops at the
        step tolerance :data:`WARM_COARSE_STEP_M`.

    Returns
    -------
    points : (N, 3) float64
    report : SolveReport or MultiscaleReport
    """
    hair = adaptable.hair
    solve_options = shape_solve_options(options)
    solver_progress = rescaled(progress, 0.1, 0.95, "solve")
    if options.method == "global":
        progress("solve", 0.1, "shape adaptation (global)")
        return solve_hairstyle(
            adaptable.shape_model, hair.offsets, initial, hair.at_root, target_query, weights, solve_options,
            gamma=gamma, backend=options.qp_backend, start=start, progress=solver_progress, should_stop=should_stop,
        )
    progress("solve", 0.1, f"shape adaptation (multi-scale, {len(adaptable.multiscale.guides)} guides)")
    with timed(timings, "distance_grid"):
        grid = DistanceGrid.build(target_query, region=grid_region(initial), near=start if warm else None,
                                  reach=WARM_GRID_REACH)
    points, report = solve_multiscale(
        hair, adaptable.multiscale, adaptable.coarse_model, adaptable.fine_source, initial, target_query,
        weights, solve_options, gamma=gamma, start=start, workers=options.workers or 1,
        chunk_particles=options.chunk_particles, grid=grid, backend=options.qp_backend,
        progress=solver_progress, should_stop=should_stop, fine_runner=fine_runner,
        coarse_step_tolerance=WARM_COARSE_STEP_M if warm else None,
    )
    timings["coarse_solve"] = report.coarse_seconds
    timings["fine_solve"] = report.fine_seconds
    return points, report


def shape_solve_options(options: RetargetOptions) -> SolveOptions:
    """The shape solve's options of a retarget's."""
    return SolveOptions(eps_c=options.eps_c, max_iterations=options.max_iterations,
                        step_tolerance=options.step_tolerance, energy_tolerance=options.energy_tolerance)


def grid_region(initial: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The box of the multi-scale solve's distance grid: the initial transfer's, grown by
    :data:`GRID_REGION_MARGIN` (``initial : (N, 3) float64``)."""
    return initial.min(axis=0) - GRID_REGION_MARGIN, initial.max(axis=0) + GRID_REGION_MARGIN


def relocate_hairline(
    adaptable: AdaptableHairstyle, target: Character, initial: np.ndarray, roots: np.ndarray, edit: HairlineEdit
) -> tuple[Relocation, np.ndarray, np.ndarray]:
    """Sec. 6: relocate the roots on the target, then the adaptive weights and a start.

    Parameters
    ----------
    initial : (N, 3) float64
        The initial transfer.
    roots : (S, 3) float64
        The roots' positions on the target before the edit.

    Returns
    -------
    relocation : Relocation
    start : (N, 3) float64
        The solvers' first iterate: each strand's initial transfer moved by its root's travel
        times ``1 - gamma`` (all of it at the root, fading along the strand as Eq. 20's
        weight rises), the roots exactly at their new places (Eq. 12's new right-hand side).
    gamma : (N,) float64
        Eq. 20's weights for Eq. 21.
    """
    hair = adaptable.hair
    relocation = relocate_roots(
        target, adaptable.anchors.face[hair.roots], adaptable.anchors.barycentric[hair.roots], edit
    )
    gamma = adaptive_weights(hair, relocation.travel)
    shift = np.repeat(relocation.roots - roots, hair.counts, axis=0)
    start = initial + (1.0 - gamma)[:, None] * shift
    start[hair.roots] = relocation.roots
    return relocation, hair.place_at_roots(start), gamma


def crossing_mask(hair: Hair, target: Character, query: MeshQuery | None = None) -> np.ndarray:
    """(N,) bool: the particles that start a segment passing through the target body between two particles
    outside it (:func:`~hairport.solver.mesh.segment_crossing.crossing_segments`, against the collision surface
    unless ``query`` is given)."""
    query = query or collision_query(target.vertices, target.faces, target.name)
    return crossing_segments(hair.points, hair.segments, hair.at_root, query).starts(hair.segments, hair.n_particles)


def penetrating_mask(hair: Hair, target: Character, query: MeshQuery | None = None) -> np.ndarray:
    """(N,) bool: non-root particles inside the target body (by its collision surface's test,
    :func:`~hairport.solver.mesh.collision.collision_query`, unless ``query`` is given); the particles
    at a root (:attr:`~hairport.solver.model.hair.Hair.at_root`) are the root."""
    query = query or collision_query(target.vertices, target.faces, target.name)
    mask = np.zeros(hair.n_particles, dtype=bool)
    free = ~hair.at_root
    mask[free] = query.inside(hair.points[free])
    return mask
