"""The ``hairport`` command line."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from .solver.errors import InputError

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


def _add_retarget(sub) -> None:
    from .solver.pipeline import METHODS

    p = sub.add_parser("retarget", help="retarget a hairstyle from a source to a target character")
    p.add_argument("--source", required=True, help="source character mesh (OBJ/PLY/GLB)")
    p.add_argument("--target", required=True, help="target character mesh, same topology")
    p.add_argument("--hair", required=True, help="hair file of the source (.data/.hair/.ply/.npz/.obj)")
    p.add_argument("--out", required=True, help="output hair file; the format follows the extension")
    p.add_argument("--source-skeleton", help="skeleton JSON of the source (default: <mesh>.skeleton.json, else glTF skin)")
    p.add_argument("--target-skeleton", help="skeleton JSON of the target (default: sidecar, glTF skin, else transferred)")
    p.add_argument("--method", default="global",
                   help=f"one of {', '.join(METHODS)}; baselines accept the suffix +pushout (default: global)")
    p.add_argument("--report", help="write metrics and per-stage timings as JSON here")
    p.add_argument("--preview", help="write a PNG preview (source vs result, penetrating particles in red)")
    p.add_argument("--units", default=None, choices=["m", "dm", "cm", "mm"],
                   help="units of the hair and of meshes without a skeleton sidecar (default m); output uses them too")
    p.add_argument("--alpha", type=float, default=3e3, help="inter-strand weight (Eq. 1)")
    p.add_argument("--beta", type=float, default=1e3, help="hair-body weight (Eq. 1)")
    p.add_argument("--eps-c", type=float, default=5e-4, help="clearance to the body in meters (Eq. 13)")
    p.add_argument("--max-iterations", type=int, default=30, help="cap on outer solver iterations")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(run=cmd_retarget)


def cmd_retarget(args: argparse.Namespace) -> int:
    from .outputs import OutputSet
    from .settings import get_settings
    from .solver import pipeline
    from .solver.characterio import load_character, resolve_skeleton_path
    from .solver.hairio import ReadLimits, format_for_path, read_hair, write_hair

    settings = get_settings()
    progress = StageProgress(args.quiet)
    units = args.units or "m"
    format_for_path(args.out)  # refuse unknown formats and options before any work
    format_for_path(args.hair)
    progress("load", 0.0, "reading inputs")
    limits = ReadLimits(settings.max_strands, settings.max_particles, settings.max_file_bytes)
    options = pipeline.RetargetOptions(method=args.method, alpha=args.alpha, beta=args.beta, eps_c=args.eps_c,
                                       max_iterations=args.max_iterations)
    options.validate()
    load = dict(max_vertices=settings.max_vertices, max_faces=settings.max_faces, max_bytes=settings.max_file_bytes)

    def mesh_units(mesh: str, skeleton: str | None) -> str | None:
        # a skeleton sidecar states its own units; --units is for meshes without one
        return None if (skeleton is not None or resolve_skeleton_path(mesh) is not None) else args.units

    source = load_character(args.source, skeleton_path=args.source_skeleton,
                            units=mesh_units(args.source, args.source_skeleton), **load)
    target = load_character(args.target, skeleton_path=args.target_skeleton,
                            units=mesh_units(args.target, args.target_skeleton), **load)
    hair = read_hair(args.hair, units=units, limits=limits)
    began = time.perf_counter()
    adaptable = pipeline.preprocess(source, hair, progress=progress)
    preprocess_seconds = time.perf_counter() - began
    result = pipeline.retarget(adaptable, target, options, progress=progress)
    report = result.report()
    report["timings_s"] = {"preprocess": preprocess_seconds, **report["timings_s"]}
    report["inputs"] = {"source": args.source, "target": args.target, "hair": args.hair,
                        "strands": hair.n_strands, "particles": hair.n_particles, "units": units}
    with OutputSet() as outputs:
        outputs.add(args.out, lambda path: write_hair(path, result.hair, units=units, format=format_for_path(args.out)))
        if args.report:
            outputs.add_json(args.report, report)
        if args.preview:
            outputs.add(args.preview, lambda path: _preview(path, adaptable, result, target))
        written = outputs.commit()
    m = result.metrics
    progress("done", 1.0, f"wrote {', '.join(str(p) for p in written)}")
    print(f"penetrating particles {m['penetrating_particles']}, mean segment angle "
          f"{m['mean_segment_angle_rad']:.4f} rad, inter-strand error {m['interstrand_error_m']:.2e} m, "
          f"max root error {m['root_to_target_max']:.1e} m")
    return 0


def _preview(path: Path, adaptable, result, target) -> None:
    from .solver.pipeline import penetrating_mask
    from .solver.preview import render_preview

    render_preview(path, [
        (adaptable.hair, adaptable.source, None, "source"),
        (result.hair, target, penetrating_mask(result.hair, target), f"result ({result.metrics['method']})"),
    ])


def _add_demo(sub) -> None:
    p = sub.add_parser("demo", help="build two MakeHuman characters and a groom, retarget, write results")
    p.add_argument("--out", default="hairport-demo", help="output folder (default ./hairport-demo)")
    p.add_argument("--style", default="fringe", help="groom style: short, long, wavy, curly, fringe")
    p.add_argument("--strands", type=int, default=200)
    p.add_argument("--particles", type=int, default=20, help="particles per strand")
    p.add_argument("--source-preset", default="average-female")
    p.add_argument("--target-preset", default="heavy-male")
    p.add_argument("--seed", type=int, default=0)
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
    from .solver.assets import fetch_makehuman_assets

    path = fetch_makehuman_assets(Path(args.cache_dir) if args.cache_dir else None)
    print(path)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="hairport", description="Retarget strand hairstyles between characters.")
    sub = parser.add_subparsers(dest="command", required=True)
    _add_retarget(sub)
    _add_demo(sub)
    _add_assets(sub)
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
