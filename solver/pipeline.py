"""The one entry point the CLI, the worker and the benchmarks call.

``preprocess(source, hair)`` computes everything that depends on the source only (the
"adaptable hairstyle"); ``retarget(adaptable, target)`` adapts it to one target: initial
transfer (Eq. 2-6), then shape adaptation (Eq. 1) or a baseline, then metrics.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from functools import cached_property

import numpy as np

from .baselines import BASELINE_METHODS, parse_method, retarget_baseline
from .character import Character, Skeleton, check_same_topology
from .energies import EnergyWeights, Neighbours, ShapeModel, knn_other_strands, laplacian_operator
from .artifact import FORMAT_VERSION, load_adaptable, save_adaptable
from .characterio import MESH_EXTENSIONS as CHARACTER_MESH_EXTENSIONS
from .characterio import load_character
from .errors import InputError
from .hairio import SUPPORTED_FORMATS, ReadLimits, read_hair, write_hair
from .geometry import MeshQuery, interpolate_barycentric
from .hair import Hair
from .metrics import hairstyle_metrics
from .distance_grid import DistanceGrid
from .guides import DEFAULT_GUIDES
from .hairline import HairlineCurve, adaptive_weights, parse_hairline_curve, read_hairline_curve
from .hairline_presets import PRESETS as HAIRLINE_PRESETS  # noqa: F401 - the CLI's and service's choices
from .hairline_presets import parse_preset
from .parameterization import PARAMETERIZATIONS  # noqa: F401 - the CLI's and service's choices
from .relocation import RELOCATION_METHODS  # noqa: F401 - the CLI's and service's choices
from .relocation import HairlineEdit, Relocation, edit_curve, relocate_roots, scalp_chart
from .multiscale import (
    DEFAULT_CHUNK_PARTICLES,
    FineSource,
    MultiscaleModel,
    MultiscaleReport,
    build_multiscale_model,
    coarse_shape_model,
    default_workers,
    fine_source,
    solve_multiscale,
)
from .qp import Cancelled, SolveOptions, SolveReport  # noqa: F401 - Cancelled is part of this module's interface
from .strand_solver import QP_BACKENDS, StrandSolveReport, solve_hairstyle
from .skeleton_transfer import ensure_skeleton
from .transfer import ANCHOR_SIGMA, SMOOTHING_EPS, Anchors, compute_anchors, place_anchors, smooth_strands, strand_laplacian

#: the shape-adaptation solvers: guides then independent strands (Sec. 5), or all strands coupled
SOLVER_METHODS = ("multiscale", "global")
METHODS = SOLVER_METHODS + BASELINE_METHODS

ProgressFn = Callable[[str, float, str], None]

#: the multi-scale solve's distance grid covers the initial transfer's box grown by this (m);
#: particles that leave it are still queried exactly, only without the grid's shortcut
GRID_REGION_MARGIN = 0.05
#: the solvers stop a strand (or the coupled guides) once an iteration lowers Eq. 1 by less
#: than this fraction (see SolveOptions.energy_tolerance)
ENERGY_TOLERANCE = 1e-3


@dataclass(frozen=True)
class PreprocessOptions:
    """Source-side parameters (Table 1, meters)."""

    k: int = 5
    sigma: float = ANCHOR_SIGMA
    guides: int = DEFAULT_GUIDES
    guide_seed: int = 0

    def validate(self) -> None:
        if self.k < 1:
            raise InputError(f"option k must be >= 1, got {self.k}", code="bad_option")
        if self.guides < 1:
            raise InputError(f"option guides must be >= 1, got {self.guides}", code="bad_option")
        if not np.isfinite(self.sigma) or self.sigma < 0:
            raise InputError(f"option sigma must be a finite non-negative number, got {self.sigma}", code="bad_option")


@dataclass(frozen=True)
class RetargetOptions:
    """Target-side parameters (Table 1, meters) and the method.

    ``method`` is ``multiscale`` (Sec. 5), ``global`` (Eq. 1 over all strands coupled) or a
    baseline name, optionally with the ``+pushout`` suffix. ``workers`` processes share the
    multi-scale fine level (``None``: the CPUs available), in chunks of ``chunk_particles``.
    ``qp_backend`` solves the coupled QPs (``global``, and the guides of ``multiscale``): the
    active-set method of :mod:`.strand_solver` or OSQP. ``hairline`` edits the front
    hairline (Sec. 6; solver methods only).
    """

    method: str = "multiscale"
    alpha: float = 3e3
    beta: float = 1e3
    eps_c: float = 5e-4
    eps_s: float = SMOOTHING_EPS
    max_iterations: int = 30
    step_tolerance: float = 1e-5
    energy_tolerance: float = ENERGY_TOLERANCE
    workers: int | None = None
    chunk_particles: int = DEFAULT_CHUNK_PARTICLES
    qp_backend: str = "active-set"
    hairline: HairlineEdit | None = None

    def validate(self) -> None:
        if self.method not in SOLVER_METHODS:
            try:
                parse_method(self.method)
            except InputError:
                raise InputError(
                    f"unknown method {self.method!r}; expected one of {', '.join(METHODS)} "
                    "(a baseline may carry the suffix +pushout)",
                    code="unknown_method",
                ) from None
        for name in ("alpha", "beta", "eps_c", "eps_s", "step_tolerance", "energy_tolerance"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise InputError(f"option {name} must be a finite non-negative number, got {value}", code="bad_option")
        if self.max_iterations < 1:
            raise InputError("option max_iterations must be >= 1", code="bad_option")
        if self.qp_backend not in QP_BACKENDS:
            raise InputError(
                f"unknown QP backend {self.qp_backend!r}; expected one of {', '.join(QP_BACKENDS)}", code="bad_option"
            )
        if self.workers is not None and self.workers < 1:
            raise InputError("option workers must be >= 1", code="bad_option")
        if self.chunk_particles < 1:
            raise InputError("option chunk_particles must be >= 1", code="bad_option")
        if self.hairline is not None:
            if self.method not in SOLVER_METHODS:
                raise InputError(
                    f"a hairline edit needs the method multiscale or global, not the baseline {self.method!r}",
                    code="bad_option",
                )
            self.hairline.validate()


@dataclass(frozen=True, eq=False)
class AdaptableHairstyle:
    """Everything retargeting needs that depends on the source only."""

    source: Character
    hair: Hair
    anchors: Anchors
    multiscale: MultiscaleModel
    options: PreprocessOptions
    bone_names: tuple[str, ...]
    timings: dict = field(default_factory=dict)

    # derived from the source only: built once, reused by every retarget of this hairstyle
    # (cached_property writes the instance __dict__ directly, which a frozen dataclass allows)
    @cached_property
    def neighbours(self) -> Neighbours:
        """Eq. 8-9 over all strands (the coupled ``global`` solve only)."""
        return knn_other_strands(self.hair.points, self.hair.strand_of, self.options.k)

    @cached_property
    def coarse_model(self) -> ShapeModel:
        """Eq. 7/10 operators of the guide hairstyle."""
        return coarse_shape_model(self.hair, self.multiscale)

    @cached_property
    def fine_source(self) -> FineSource:
        """Source-only arrays of the fine level."""
        return fine_source(self.hair, self.multiscale)

    @cached_property
    def shape_model(self) -> ShapeModel:
        """Eq. 7/10 operators of the whole hairstyle."""
        n = self.hair.n_particles
        K = laplacian_operator(self.neighbours, np.arange(n), n)
        return ShapeModel.build(self.hair.points, self.hair.segments, K)

    @cached_property
    def strand_laplacian(self):
        """Eq. 5's per-strand Laplacian of the source, ``(N, N)`` csr_matrix."""
        return strand_laplacian(self.hair.points, self.hair.offsets)


@dataclass(eq=False)
class RetargetResult:
    """A retargeted hairstyle with what was measured on the way (``relocation``: the hairline
    edit's relocated roots and deformed scalp, when one was asked for)."""

    hair: Hair
    initial: Hair
    metrics: dict
    timings: dict
    solve: SolveReport | StrandSolveReport | MultiscaleReport | None = None
    relocation: Relocation | None = None

    def report(self) -> dict:
        """JSON-ready report: metrics, per-stage timings (s), solver trace."""
        out = {"metrics": self.metrics, "timings_s": self.timings}
        if self.solve is not None:
            out["solver"] = asdict(self.solve)
        return out


def _noop(stage: str, fraction: float, message: str) -> None:
    return None


def preprocess(
    source: Character,
    hair: Hair,
    options: PreprocessOptions = PreprocessOptions(),
    progress: ProgressFn | None = None,
) -> AdaptableHairstyle:
    """Compute the adaptable hairstyle: anchors (Eq. 2) and kNN sets/weights (Eq. 8-9).

    Parameters
    ----------
    source : Character
        Rigged source character (skeleton and skin weights required).
    hair : Hair
        The hairstyle made for ``source``.
    """
    progress = progress or _noop
    options.validate()
    if source.skeleton is None or source.weights is None:
        raise InputError("the source character needs a skeleton with skin weights", source.name, "no_skeleton")
    timings = {}
    began = time.perf_counter()
    progress("anchors", 0.0, "anchoring particles to bones")
    query = MeshQuery(source.vertices, source.faces)
    anchors = compute_anchors(source, hair.points, hair.is_root, query, options.sigma)
    timings["anchors"] = time.perf_counter() - began
    began = time.perf_counter()
    progress("guides", 0.5, "selecting guides and inter-strand neighbours")
    multiscale = build_multiscale_model(hair, options.guides, options.k, options.guide_seed)
    timings["guides"] = time.perf_counter() - began
    progress("preprocess", 1.0, "done")
    return AdaptableHairstyle(source, hair, anchors, multiscale, options, source.skeleton.names, timings)


def prepare_target(adaptable: AdaptableHairstyle, target: Character) -> Character:
    """Check topology, give the target a skeleton if it has none, and check its bones."""
    check_same_topology(adaptable.source, target)
    target = ensure_skeleton(adaptable.source, target)
    if target.skeleton.names != adaptable.bone_names:
        missing = sorted(set(adaptable.bone_names) - set(target.skeleton.names))
        if missing:
            raise InputError(f"target skeleton lacks bones {missing[:5]}", target.name, "bad_skeleton")
        order = [target.skeleton.names.index(name) for name in adaptable.bone_names]
        parents = np.array([
            adaptable.bone_names.index(target.skeleton.names[p]) if p >= 0 else -1 for p in target.skeleton.parents[order]
        ])
        skeleton = Skeleton(adaptable.bone_names, parents, target.skeleton.heads[order], target.skeleton.tails[order])
        weights = target.weights[:, order] if target.weights is not None else None
        target = Character(target.vertices, target.faces, skeleton, weights, target.name)
    return target


def initial_transfer(
    adaptable: AdaptableHairstyle,
    target: Character,
    eps_s: float = SMOOTHING_EPS,
    query: MeshQuery | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 3 then Eq. 4-6.

    Returns
    -------
    initial : (N, 3) float64
        ``p-hat``.
    unsmooth : (N,) bool
        Particles that were smoothed.
    """
    hair = adaptable.hair
    anchored = place_anchors(adaptable.anchors, target, query)
    return smooth_strands(anchored, hair.points, hair.offsets, eps_s, laplacian=adaptable.strand_laplacian)


def root_targets(adaptable: AdaptableHairstyle, target: Character) -> np.ndarray:
    """Where each root belongs on the target: its anchor face and barycentrics, ``(S, 3)``."""
    roots = adaptable.hair.roots
    return interpolate_barycentric(
        target.vertices, target.faces, adaptable.anchors.face[roots], adaptable.anchors.barycentric[roots]
    )


def retarget(
    adaptable: AdaptableHairstyle,
    target: Character,
    options: RetargetOptions = RetargetOptions(),
    progress: ProgressFn | None = None,
    should_stop: Callable[[], bool] | None = None,
) -> RetargetResult:
    """Adapt the hairstyle to ``target``.

    Parameters
    ----------
    adaptable : AdaptableHairstyle
        From :func:`preprocess`.
    target : Character
        Same topology as the source; a skeleton is transferred when it has none.
    options : RetargetOptions
    progress : callable(stage, fraction, message), optional
    should_stop : callable() -> bool, optional
        Polled between solver iterations (cancellation).
    """
    options.validate()
    progress = progress or _noop
    hair = adaptable.hair
    timings: dict[str, float] = {}

    began = time.perf_counter()
    progress("prepare", 0.0, "checking the target")
    target = prepare_target(adaptable, target)
    target_query = MeshQuery(target.vertices, target.faces)
    timings["prepare"] = time.perf_counter() - began

    began = time.perf_counter()
    progress("initial_transfer", 0.05, "initial transfer")
    initial, unsmooth = initial_transfer(adaptable, target, options.eps_s, target_query)
    timings["initial_transfer"] = time.perf_counter() - began

    roots = root_targets(adaptable, target)
    start = gamma = relocation = None
    if options.hairline is not None:
        progress("hairline", 0.07, f"relocating the roots for the hairline edit {options.hairline.describe()}")
        relocation, start, gamma = relocate_hairline(adaptable, target, initial, roots, options.hairline)
        roots = relocation.roots
        timings["hairline"] = relocation.report["seconds"]

    model = adaptable.shape_model
    weights = EnergyWeights(options.alpha, options.beta)
    solve_report = None
    began = time.perf_counter()
    solve_options = SolveOptions(
        eps_c=options.eps_c, max_iterations=options.max_iterations, step_tolerance=options.step_tolerance,
        energy_tolerance=options.energy_tolerance,
    )

    def solver_progress(fraction: float, message: str) -> None:
        progress("solve", 0.1 + 0.85 * fraction, message)

    if options.method == "global":
        progress("solve", 0.1, "shape adaptation (global)")
        points, solve_report = solve_hairstyle(
            model, hair.offsets, initial, hair.is_root, target_query, weights, solve_options, gamma=gamma,
            backend=options.qp_backend, start=start, progress=solver_progress, should_stop=should_stop,
        )
        timings["solve"] = time.perf_counter() - began
    elif options.method == "multiscale":
        progress("solve", 0.1, f"shape adaptation (multi-scale, {len(adaptable.multiscale.guides)} guides)")
        reach = (initial.min(axis=0) - GRID_REGION_MARGIN, initial.max(axis=0) + GRID_REGION_MARGIN)
        grid = DistanceGrid.build(target_query, region=reach)
        timings["distance_grid"] = time.perf_counter() - began
        points, solve_report = solve_multiscale(
            hair, adaptable.multiscale, adaptable.coarse_model, adaptable.fine_source, initial, target_query,
            weights, solve_options, gamma=gamma, start=start, workers=options.workers or default_workers(),
            chunk_particles=options.chunk_particles, grid=grid, backend=options.qp_backend,
            progress=solver_progress, should_stop=should_stop,
        )
        timings["coarse_solve"] = solve_report.coarse_seconds
        timings["fine_solve"] = solve_report.fine_seconds
        timings["solve"] = time.perf_counter() - began
    else:
        progress("baseline", 0.1, f"baseline {options.method}")
        base, pushout = parse_method(options.method)
        points = retarget_baseline(
            base, adaptable.source, target, hair, pushout=pushout, clearance=options.eps_c, target_query=target_query
        ).points
        timings["baseline"] = time.perf_counter() - began

    began = time.perf_counter()
    progress("metrics", 0.95, "measuring")
    metrics = hairstyle_metrics(
        points, hair.points, initial, hair.is_root, roots, model, target_query, options.eps_c, weights,
    )
    metrics["method"] = options.method
    if relocation is not None:
        metrics["hairline"] = relocation.report
    metrics["smoothed_particles"] = int(unsmooth.sum())
    metrics["fallback_anchors"] = int(adaptable.anchors.fallback.sum())
    timings["metrics"] = time.perf_counter() - began
    progress("done", 1.0, "done")
    return RetargetResult(
        hair.with_points(points), hair.with_points(initial), metrics, timings, solve_report, relocation
    )


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
    return relocation, start, gamma


def hairline_document(adaptable: AdaptableHairstyle, target: Character, preset: str | None = None,
                      parameterization: str = "harmonic") -> dict:
    """The target's current front hairline (or a preset's edit of it) as a curve document,
    ``{"units": "m", "points": [[x, y, z], ...], "turning_points": [...]}``, ready to be
    edited and passed back as a hairline curve (same ends, same turning points)."""
    target = prepare_target(adaptable, target)
    roots = adaptable.hair.roots
    setup = scalp_chart(target, adaptable.anchors.face[roots], parameterization)
    if preset is None:
        curve = HairlineCurve(setup.rest[setup.front], setup.turning)
    else:
        name, amount = parse_preset(preset)
        curve = edit_curve(setup, HairlineEdit(preset=name, amount=amount))
    points, turning = np.round(curve.points, 7).tolist(), np.asarray(curve.turning_points).tolist()
    return {"units": "m", "points": points, "turning_points": turning}


def hairline_edit_from_request(document: dict) -> HairlineEdit:
    """A validated hairline edit from the API's ``hairline`` object: ``preset`` with
    ``amount``, or ``curve`` (a curve document), plus ``method`` and ``parameterization``."""
    preset, curve = document.get("preset"), document.get("curve")
    return hairline_edit(
        preset=None if preset is None else f"{preset}:{document.get('amount', 1.0)}", curve=curve,
        method=document.get("method", "membrane"), parameterization=document.get("parameterization", "harmonic"),
    )


def hairline_edit(
    preset: str | None = None,
    curve_path=None,
    curve: dict | None = None,
    method: str = "membrane",
    parameterization: str = "harmonic",
) -> HairlineEdit:
    """A validated hairline edit from a preset ``NAME[:AMOUNT]``, a curve JSON file or a
    parsed curve document (exactly one)."""
    given = sum(x is not None for x in (preset, curve_path, curve))
    if given != 1:
        raise InputError("give exactly one of a hairline preset, a curve file or a curve", code="bad_option")
    if preset is not None:
        name, amount = parse_preset(preset)
        edit = HairlineEdit(preset=name, amount=amount, method=method, parameterization=parameterization)
    else:
        parsed = read_hairline_curve(curve_path) if curve_path is not None else parse_hairline_curve(curve)
        edit = HairlineEdit(curve=parsed, method=method, parameterization=parameterization)
    edit.validate()
    return edit


def penetrating_mask(hair: Hair, target: Character, query: MeshQuery | None = None) -> np.ndarray:
    """(N,) bool: non-root particles inside the target body."""
    query = query or MeshQuery(target.vertices, target.faces)
    mask = np.zeros(hair.n_particles, dtype=bool)
    free = ~hair.is_root
    mask[free] = query.signed_distance(hair.points[free]).distance < 0.0
    return mask


# --------------------------------------------------------------------------------------
# files: the entry points the service and the worker use (they import nothing else)
# --------------------------------------------------------------------------------------

#: hair file formats read and written (file extensions without the dot)
HAIR_FORMATS = SUPPORTED_FORMATS
#: character mesh extensions read
MESH_EXTENSIONS = CHARACTER_MESH_EXTENSIONS
ARTIFACT_FORMAT_VERSION = FORMAT_VERSION


def load_character_file(
    mesh_path, skeleton_path=None, units: str | None = None, *, max_vertices: int, max_faces: int, max_bytes: int
) -> Character:
    """A character from a mesh file and an optional skeleton JSON (see :mod:`.characterio`)."""
    return load_character(
        mesh_path, skeleton_path=skeleton_path, units=units, max_vertices=max_vertices, max_faces=max_faces,
        max_bytes=max_bytes,
    )


def read_hair_file(path, units: str = "m", *, max_strands: int, max_particles: int, max_bytes: int) -> Hair:
    """A hairstyle from a file, validated against the limits (see :mod:`.hairio`)."""
    return read_hair(path, units=units, limits=ReadLimits(max_strands, max_particles, max_bytes))


def write_hair_file(path, hair: Hair, format: str, units: str = "m") -> None:
    """Write ``hair`` in ``format`` (one of :data:`HAIR_FORMATS`)."""
    write_hair(path, hair, units=units, format=format)


def save_adaptable_file(adaptable: AdaptableHairstyle, path) -> None:
    """Write the adaptable hairstyle artifact (see :mod:`.artifact`)."""
    save_adaptable(adaptable, path)


def load_adaptable_file(path) -> AdaptableHairstyle:
    """Read an adaptable hairstyle artifact; refuses other versions and damaged files."""
    return load_adaptable(path)


def write_preview(path, adaptable: AdaptableHairstyle, result: RetargetResult, target: Character) -> None:
    """PNG: the source hairstyle next to the result, penetrating particles highlighted."""
    from .preview import render_preview

    render_preview(path, [
        (adaptable.hair, adaptable.source, None, "source"),
        (result.hair, target, penetrating_mask(result.hair, target), f"result ({result.metrics['method']})"),
    ])
