"""What the commands share: exit codes, progress lines, source/units arguments, and loading the inputs."""

from __future__ import annotations

import argparse
import sys
import time

from hairport import solver
from hairport.solver import InputError

EXIT_BAD_INPUT = 2
EXIT_FAILURE = 1


class StageProgress:
    """Prints one line per pipeline stage (and solver iterations) to stderr (a :data:`hairport.solver.ProgressFn`)."""

    def __init__(self, quiet: bool = False) -> None:
        self.quiet = quiet
        self.began = time.perf_counter()
        self.stage = None

    def __call__(self, stage: str, fraction: float, message: str) -> None:
        if self.quiet:
            return
        elapsed = time.perf_counter() - self.began
        print(f"[{elapsed:7.2f}s] {stage:<17} {100 * fraction:5.1f}%  {message}", file=sys.stderr, flush=True)


def add_source_arguments(p: argparse.ArgumentParser, required: bool) -> None:
    p.add_argument("--source", required=required, help=f"source character mesh ({'/'.join(solver.MESH_EXTENSIONS)})")
    p.add_argument("--hair", required=required,
                   help=f"hair file of the source ({'/'.join('.' + name for name in solver.HAIR_FORMATS)})")
    p.add_argument("--source-skeleton", help="skeleton JSON of the source (default: <mesh>.skeleton.json, else glTF skin)")
    p.add_argument("--guides", type=int, default=None,
                   help="guide strands of the multi-scale solve (default 300, or every strand if fewer)")
    p.add_argument("--k", type=int, default=solver.PreprocessOptions.k,
                   help="inter-strand neighbours per particle (Eq. 8)")


def add_units(p: argparse.ArgumentParser) -> None:
    p.add_argument("--units", default=None, choices=solver.UNITS,
                   help="units of the hair and of meshes without a skeleton sidecar (default m); output uses them too")


def preprocess_options(args: argparse.Namespace) -> solver.PreprocessOptions:
    options = solver.PreprocessOptions(k=args.k, guides=solver.DEFAULT_GUIDES if args.guides is None else args.guides)
    options.validate()
    return options


def mesh_limits(settings) -> dict:
    return dict(max_vertices=settings.max_vertices, max_faces=settings.max_faces, max_bytes=settings.max_file_bytes)


def mesh_units(args: argparse.Namespace, mesh: str, skeleton: str | None) -> str | None:
    # a skeleton sidecar states its own units; --units is for meshes without one
    return None if (skeleton is not None or solver.resolve_skeleton_path(mesh) is not None) else args.units


def load_target(args: argparse.Namespace, settings) -> solver.Character:
    return solver.load_character(args.target, skeleton_path=args.target_skeleton,
                                 units=mesh_units(args, args.target, args.target_skeleton), **mesh_limits(settings))


def load_source(args: argparse.Namespace, settings, progress) -> tuple[solver.Character, solver.Hair]:
    """Source character and hair from --source/--hair, with the configured limits."""
    limits = solver.ReadLimits(settings.max_strands, settings.max_particles, settings.max_file_bytes)
    progress("load", 0.0, "reading the source")
    source = solver.load_character(args.source, skeleton_path=args.source_skeleton,
                                   units=mesh_units(args, args.source, args.source_skeleton), **mesh_limits(settings))
    hair = solver.read_hair(args.hair, units=args.units or "m", limits=limits)
    return source, hair


def check_source_arguments(args: argparse.Namespace) -> None:
    if args.adaptable and (args.source or args.hair or args.source_skeleton or args.guides is not None):
        raise InputError("give either --adaptable or --source with --hair, not both "
                         "(guides and neighbours are fixed when the artifact is made)", code="bad_option")
    if not args.adaptable and not (args.source and args.hair):
        raise InputError("give --adaptable, or --source with --hair", code="bad_option")


def adaptable_from_args(args: argparse.Namespace, settings, progress) -> tuple[solver.AdaptableHairstyle, float]:
    """The adaptable hairstyle of --adaptable, or preprocessed from --source/--hair, and the
    seconds preprocessing took (0 for an artifact)."""
    check_source_arguments(args)
    if args.adaptable:
        progress("load", 0.0, "reading the adaptable hairstyle")
        return solver.load_adaptable(args.adaptable), 0.0
    options = preprocess_options(args)
    source, hair = load_source(args, settings, progress)
    began = time.perf_counter()
    adaptable = solver.preprocess(source, hair, options, progress=progress)
    return adaptable, time.perf_counter() - began
