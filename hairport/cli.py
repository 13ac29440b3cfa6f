"""The ``hairport`` command line."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from hairport.solver.model.errors import InputError

EXIT_BAD_INPUT = 2
EXIT_FAILURE = 1


class StageProgress:
    """Prints one line per pipeline stage (and solver iterations) to stderr."""

    def __init__(self, quiet: bool = False) -> None:
        self.quiet = quiet
        self.began = time.perf_counter()
        self.stage = None

    def __call__(self, stage: str, fraction: float, message: str) -> None:
        if self.quiet:
            return
        elapsed = time.perf_counter() - self.began
        print(f"[{elapsed:7.2f}s] {stage:<17} {100 * fraction:5.1f}%  {message}", file=sys.stderr, flush=True)


def _add_source_arguments(p, required: bool) -> None:
    p.add_argument("--source", required=required, help="source character mesh (OBJ/PLY/GLB)")
    p.add_argument("--hair", required=required, help="hair file of the source (.data/.hair/.ply/.npz/.obj)")
    p.add_argument("--source-skeleton", help="skeleton JSON of the source (default: <mesh>.skeleton.json, else glTF skin)")
    p.add_argument("--guides", type=int, default=None,
                   help="guide strands of the multi-scale solve (default 300, or every strand if fewer)")
    p.add_argument("--k", type=int, default=5, help="inter-strand neighbours per particle (Eq. 8)")


def _add_units(p) -> None:
    p.add_argument("--units", default=None, choices=["m", "dm", "cm", "mm"],
                   help="units of the hair and of meshes without a skeleton sidecar (default m); output uses them too")


def _add_preprocess(sub) -> None:
    from hairport.solver.artifact import EXTENSION as ARTIFACT_EXTENSION

    p = sub.add_parser("preprocess", help="compute the adaptable hairstyle of a source groom once (.hpa)")
    _add_source_arguments(p, required=True)
    p.add_argument("--out", required=True, help=f"artifact file to write (extension {ARTIFACT_EXTENSION})")
    _add_units(p)
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(run=cmd_preprocess)


def _add_retarget(sub) -> None:
    from hairport.solver.adaptation.coupled import QP_BACKENDS
    from hairport.solver.options import METHODS

    p = sub.add_parser("retarget", help="retarget a hairstyle from a source to a target character")
    p.add_argument("--adaptable", help="adaptable hairstyle from `hairport preprocess` (instead of --source/--hair)")
    _add_source_arguments(p, required=False)
    p.add_argument("--target", required=True, help="target character mesh, same topology")
    p.add_argument("--out", required=True, help="output hair file; the format follows the extension")
    p.add_argument("--target-skeleton", help="skeleton JSON of the target (default: sidecar, glTF skin, else transferred)")
    p.add_argument("--method", default="multiscale",
                   help=f"one of {', '.join(METHODS)}; baselines accept the suffix +pushout (default: multiscale)")
    p.add_argument("--report", help="write metrics and per-stage timings as JSON here")
    p.add_argument("--preview", help="write a PNG preview (source vs result, penetrating particles in red)")
    _add_units(p)
    p.add_argument("--alpha", type=float, default=3e3, help="inter-strand weight (Eq. 1)")
    p.add_argument("--beta", type=float, default=1e3, help="hair-body weight (Eq. 1)")
    p.add_argument("--eps-c", type=float, default=5e-4, help="clearance to the body in meters (Eq. 13)")
    p.add_argument("--max-iterations", type=int, default=30, help="cap on outer solver iterations")
    p.add_argument("--workers", type=int, default=None, help="processes for the multi-scale fine level (default: CPUs)")
    p.add_argument("--qp-backend", default="active-set", choices=QP_BACKENDS,
                   help="solver of the coupled QPs (default active-set)")
    _add_hairline_arguments(p)
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(run=cmd_retarget)


def _add_hairline_arguments(p) -> None:
    from hairport.solver.mesh.parameterization import PARAMETERIZATIONS
    from hairport.solver.pipeline import HAIRLINE_PRESETS, RELOCATION_METHODS

    edit = p.add_mutually_exclusive_group()
    edit.add_argument("--hairline", metavar="PRESET[:AMOUNT]",
                      help=f"edit the front hairline: one of {', '.join(HAIRLINE_PRESETS)}, "
                           "amount in [0, 1] (default 1)")
    edit.add_argument("--hairline-curve", metavar="FILE.json",
                      help='edit the front hairline to a drawn curve: {"units": "m", "points": [[x, y, z], ...], '
                           '"turning_points": [i, ...]} (see `hairport hairline`)')
    p.add_argument("--hairline-method", default="membrane", choices=RELOCATION_METHODS,
                   help="how the roots follow the hairline: the embedded membrane (default) or a baseline")
    p.add_argument("--parameterization", default="harmonic", choices=PARAMETERIZATIONS,
                   help="head parameterization the scalp moves in (default harmonic)")


def _hairline_edit(args: argparse.Namespace):
    from hairport.solver import pipeline

    if args.hairline is None and args.hairline_curve is None:
        return None
    return pipeline.hairline_edit(preset=args.hairline, curve_path=args.hairline_curve,
                                  method=args.hairline_method, parameterization=args.parameterization)


def _preprocess_options(args: argparse.Namespace):
    from hairport.solver import pipeline
    from hairport.solver.adaptation.guides import DEFAULT_GUIDES

    options = pipeline.PreprocessOptions(k=args.k, guides=DEFAULT_GUIDES if args.guides is None else args.guides)
    options.validate()
    return options


def _load_source(args: argparse.Namespace, settings, progress):
    """Source character and hair from --source/--hair, with the configured limits."""
    from hairport.solver.io.character import load_character
    from hairport.solver.io.hair import ReadLimits, read_hair

    limits = ReadLimits(settings.max_strands, settings.max_particles, settings.max_file_bytes)
    progress("load", 0.0, "reading the source")
    source = load_character(args.source, skeleton_path=args.source_skeleton,
                            units=_mesh_units(args, args.source, args.source_skeleton), **_mesh_limits(settings))
    hair = read_hair(args.hair, units=args.units or "m", limits=limits)
    return source, hair


def _mesh_limits(settings) -> dict:
    return dict(max_vertices=settings.max_vertices, max_faces=settings.max_faces, max_bytes=settings.max_file_bytes)


def _mesh_units(args: argparse.Namespace, mesh: str, skeleton: str | None) -> str | None:
    from hairport.solver.io.character import resolve_skeleton_path

    # a skeleton sidecar states its own units; --units is for meshes without one
    return None if (skeleton is not None or resolve_skeleton_path(mesh) is not None) else args.units


def cmd_preprocess(args: argparse.Namespace) -> int:
    from hairport.solver import pipeline
    from hairport.solver.artifact import EXTENSION as ARTIFACT_EXTENSION
    from hairport.solver.artifact import save_adaptable
    from hairport.solver.io.hair import format_for_path

    from .outputs import OutputSet
    from .settings import get_settings

    settings = get_settings()
    progress = StageProgress(args.quiet)
    if not args.out.endswith(ARTIFACT_EXTENSION):
        raise InputError(f"the artifact file must end in {ARTIFACT_EXTENSION}", args.out, "unknown_format")
    format_for_path(args.hair)
    options = _preprocess_options(args)
    source, hair = _load_source(args, settings, progress)
    adaptable = pipeline.preprocess(source, hair, options, progress=progress)
    with OutputSet() as outputs:
        outputs.add(args.out, lambda path: save_adaptable(adaptable, path))
        outputs.commit()
    print(f"{args.out}: {hair.n_strands} strands, {hair.n_particles} particles, "
          f"{len(adaptable.multiscale.guides)} guides")
    return 0


def cmd_retarget(args: argparse.Namespace) -> int:
    from hairport.solver import pipeline
    from hairport.solver.io.character import load_character
    from hairport.solver.io.hair import format_for_path, write_hair

    from .outputs import OutputSet
    from .settings import get_settings

    settings = get_settings()
    progress = StageProgress(args.quiet)
    units = args.units or "m"
    _check_source_arguments(args)
    format_for_path(args.out)  # refuse unknown formats and options before any work
    if args.hair:
        format_for_path(args.hair)
    options = pipeline.RetargetOptions(method=args.method, alpha=args.alpha, beta=args.beta, eps_c=args.eps_c,
                                       max_iterations=args.max_iterations, workers=args.workers,
                                       qp_backend=args.qp_backend, hairline=_hairline_edit(args))
    options.validate()
    adaptable, preprocess_seconds = _adaptable_from_args(args, settings, progress)
    inputs = {"adaptable": args.adaptable} if args.adaptable else {"source": args.source, "hair": args.hair}
    target = load_character(args.target, skeleton_path=args.target_skeleton,
                            units=_mesh_units(args, args.target, args.target_skeleton), **_mesh_limits(settings))
    result = pipeline.retarget(adaptable, target, options, progress=progress)
    hair = adaptable.hair
    report = result.report()
    report["timings_s"] = {"preprocess": preprocess_seconds, **report["timings_s"]}
    report["inputs"] = {**inputs, "target": args.target, "strands": hair.n_strands, "particles": hair.n_particles,
                        "guides": len(adaptable.multiscale.guides), "units": units}
    with OutputSet() as outputs:
        outputs.add(args.out, lambda path: write_hair(path, result.hair, units=units, format=format_for_path(args.out)))
        if args.report:
            outputs.add_json(args.report, report)
        if args.preview:
            outputs.add(args.preview, lambda path: pipeline.write_preview(path, adaptable, result, target))
        written = outputs.commit()
    m = result.metrics
    progress("done", 1.0, f"wrote {', '.join(str(p) for p in written)}")
    print(f"penetrating particles {m['penetrating_particles']}, mean segment angle "
          f"{m['mean_segment_angle_rad']:.4f} rad, inter-strand error {m['interstrand_error_m']:.2e} m, "
          f"max root error {m['root_to_target_max']:.1e} m")
    if "hairline" in m:
        h = m["hairline"]
        print(f"hairline {h['edit']} ({h['method']}): {h['roots_moved']} roots moved (largest "
              f"{100 * h['max_travel_m']:.2f} cm), density change L1 {h['density_change_l1']:.3f} "
              f"Linf {h['density_change_linf']:.3f}, relocation {h['seconds']:.2f} s")
    return 0


def _add_demo(sub) -> None:
    p = sub.add_parser("demo", help="build two MakeHuman characters and a groom, retarget, write results")
    p.add_argument("--out", default="hairport-demo", help="output folder (default ./hairport-demo)")
    p.add_argument("--style", default="fringe", help="groom style: short, long, wavy, curly, fringe")
    p.add_argument("--strands", type=int, default=200)
    p.add_argument("--particles", type=int, default=20, help="particles per strand")
    p.add_argument("--source-preset", default="average-female")
    p.add_argument("--target-preset", default="heavy-male")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--hairline", default="widows-peak:0.7",
                   help="also retarget with this hairline edit, PRESET[:AMOUNT] ('none' to skip)")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(run=cmd_demo)


def cmd_demo(args: argparse.Namespace) -> int:
    from .demo import run_demo

    return run_demo(args)


def _add_assets(sub) -> None:
    p = sub.add_parser("assets", help="manage the downloaded MakeHuman assets")
    asub = p.add_subparsers(dest="assets_command", required=True)
    f = asub.add_parser("fetch", help="download (once) and cache the CC0 MakeHuman assets")
    f.add_argument("--cache-dir", help="cache folder (default: $HAIRPORT_CACHE_DIR or ~/.cache/hairport)")
    f.set_defaults(run=cmd_assets_fetch)


def cmd_assets_fetch(args: argparse.Namespace) -> int:
    from hairport.solver.synthetic.assets import fetch_makehuman_assets

    path = fetch_makehuman_assets(Path(args.cache_dir) if args.cache_dir else None)
    print(path)
    return 0


def _add_serve(sub) -> None:
    p = sub.add_parser("serve", help="run the HTTP API (uvicorn)")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=8000)
    p.add_argument("--embedded", action="store_true",
                   help="run a worker inside the server on an in-memory queue (no Redis; for a laptop)")
    p.set_defaults(run=cmd_serve)


def cmd_serve(args: argparse.Namespace) -> int:
    import uvicorn

    from .service.app import create_app
    from .service.auth import check_configuration
    from .settings import get_settings

    try:
        check_configuration(get_settings())
    except RuntimeError as error:
        print(f"hairport: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.embedded:
        from .worker.embedded import start_embedded_worker

        thread = start_embedded_worker()
        app = create_app(readiness=lambda: {"redis": True, "worker": thread.is_alive()}, queue_depths=lambda: {})
    else:
        app = create_app()
    uvicorn.run(app, host=args.host, port=args.port)
    return 0


def _add_worker(sub) -> None:
    p = sub.add_parser("worker", help="run a Celery worker against HAIRPORT_REDIS_URL")
    p.add_argument("--queues", default="preprocess,retarget", help="comma-separated queues to consume")
    p.add_argument("--concurrency", type=int, default=1, help="jobs run at once (processes)")
    p.add_argument("--loglevel", default="INFO")
    p.add_argument("--hostname", default="hairport@%h", help="worker name (%%h: host name)")
    p.set_defaults(run=cmd_worker)


def cmd_worker(args: argparse.Namespace) -> int:
    from .worker.app import celery_app

    celery_app.worker_main(["worker", "-Q", args.queues, "-c", str(args.concurrency), "--loglevel", args.loglevel,
                            "-n", args.hostname])
    return 0


def _add_purge(sub) -> None:
    p = sub.add_parser("purge", help="delete stored files and records older than HAIRPORT_RETENTION_DAYS")
    p.set_defaults(run=cmd_purge)


def cmd_purge(args: argparse.Namespace) -> int:
    from .settings import get_settings
    from .worker.jobs import get_storage

    settings = get_settings()
    removed = get_storage(settings).purge(settings.retention_days * 86400.0)
    print(f"removed {removed} files older than {settings.retention_days:g} days from {settings.storage_dir}")
    return 0


def _add_hairline(sub) -> None:
    p = sub.add_parser("hairline", help="write a target's current front hairline (or a preset's edit) as curve JSON")
    p.add_argument("--adaptable", help="adaptable hairstyle from `hairport preprocess` (instead of --source/--hair)")
    _add_source_arguments(p, required=False)
    p.add_argument("--target", required=True, help="target character mesh, same topology")
    p.add_argument("--target-skeleton", help="skeleton JSON of the target")
    p.add_argument("--preset", metavar="PRESET[:AMOUNT]", help="write this preset's edit instead of the current hairline")
    p.add_argument("--out", required=True, help="curve JSON to write")
    _add_units(p)
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(run=cmd_hairline)


def _check_source_arguments(args: argparse.Namespace) -> None:
    if args.adaptable and (args.source or args.hair or args.source_skeleton or args.guides is not None):
        raise InputError("give either --adaptable or --source with --hair, not both "
                         "(guides and neighbours are fixed when the artifact is made)", code="bad_option")
    if not args.adaptable and not (args.source and args.hair):
        raise InputError("give --adaptable, or --source with --hair", code="bad_option")


def _adaptable_from_args(args: argparse.Namespace, settings, progress):
    """The adaptable hairstyle of --adaptable, or preprocessed from --source/--hair, and the
    seconds preprocessing took (0 for an artifact)."""
    from hairport.solver import pipeline
    from hairport.solver.artifact import load_adaptable

    _check_source_arguments(args)
    if args.adaptable:
        progress("load", 0.0, "reading the adaptable hairstyle")
        return load_adaptable(args.adaptable), 0.0
    preprocess_options = _preprocess_options(args)
    source, hair = _load_source(args, settings, progress)
    began = time.perf_counter()
    adaptable = pipeline.preprocess(source, hair, preprocess_options, progress=progress)
    return adaptable, time.perf_counter() - began


def cmd_hairline(args: argparse.Namespace) -> int:
    from hairport.solver import pipeline
    from hairport.solver.io.character import load_character

    from .outputs import OutputSet
    from .settings import get_settings

    settings = get_settings()
    progress = StageProgress(args.quiet)
    adaptable, _ = _adaptable_from_args(args, settings, progress)
    target = load_character(args.target, skeleton_path=args.target_skeleton,
                            units=_mesh_units(args, args.target, args.target_skeleton), **_mesh_limits(settings))
    document = pipeline.hairline_document(adaptable, target, args.preset)
    with OutputSet() as outputs:
        outputs.add_json(args.out, document)
        outputs.commit()
    print(f"{args.out}: front hairline of {len(document['points'])} points, turning points "
          f"{document['turning_points']}")
    return 0


def _add_openapi(sub) -> None:
    p = sub.add_parser("openapi", help="print or write the OpenAPI contract of the HTTP API (YAML)")
    p.add_argument("--out", help="write here instead of standard output")
    p.set_defaults(run=cmd_openapi)


def openapi_yaml() -> str:
    """The API's OpenAPI document as YAML (what openapi.yaml holds)."""
    import yaml

    from .service.app import create_app
    from .settings import Settings

    app = create_app(Settings(insecure_dev=True), readiness=lambda: {}, queue_depths=lambda: {})
    return yaml.safe_dump(app.openapi(), sort_keys=False, allow_unicode=True)


def cmd_openapi(args: argparse.Namespace) -> int:
    text = openapi_yaml()
    if args.out:
        from .outputs import OutputSet

        with OutputSet() as outputs:
            outputs.add(args.out, lambda path: path.write_text(text))
            outputs.commit()
    else:
        sys.stdout.write(text)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="hairport", description="Retarget strand hairstyles between characters.")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_preprocess(sub)
    _add_retarget(sub)
    _add_demo(sub)
    _add_assets(sub)
    _add_serve(sub)
    _add_worker(sub)
    _add_purge(sub)
    _add_openapi(sub)
    _add_hairline(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.run(args)
    except InputError as error:
        print(f"hairport: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except FileNotFoundError as error:
        print(f"hairport: error: {error.filename or error}: file not found", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as error:
        print(f"hairport: error: {error.filename or 'output'}: {error.strerror or error}", file=sys.stderr)
        return EXIT_FAILURE
    except KeyboardInterrupt:
        print("hairport: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
