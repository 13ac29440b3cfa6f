"""What the commands share: exit codes, progress lines, source/units arguments, and loading the inputs."""

from __future__ import annotations

import argparse
import sys
import time
from contextlib import contextmanager

from hairport import solver
from hairport.solver import InputError
from hairport.solver import options as solver_options

EXIT_BAD_INPUT = 2
EXIT_FAILURE = 1
#: the command line reads the user's own files: a USD stage composes the sublayers and references it
#: names, a .gltf reads the buffer files beside it (the service and the worker, reading uploads, never do)
LOCAL_FILES = {"allow_external_files": True}


def print_warning(text: str) -> None:
    """One ``hairport: warning:`` line on stderr (a message of several lines stays one line)."""
    print(f"hairport: warning: {' '.join(str(text).split())}", file=sys.stderr, flush=True)


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


def option_type(name: str):
    """An argparse ``type`` for option ``name``: parses it and checks the solver's range
    (:data:`hairport.solver_options.OPTION_RANGES`); argparse exits 2 naming the option and its range."""
    spec = solver_options.OPTION_RANGES[name]

    def parse(text: str):
        try:
            value = int(text) if spec.integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{'an integer' if spec.integer else 'a number'} "
                                             f"{spec.text()} expected, got {text!r}") from None
        try:
            spec.check(name, value)
        except InputError as error:
            raise argparse.ArgumentTypeError(error.problem) from None
        return value

    parse.__name__ = name  # argparse names the type in its messages
    return parse


def option_help(name: str, note: str = "") -> str:
    spec = solver_options.OPTION_RANGES[name]
    return f"{spec.description}, {spec.text()}" + (f"; {note}" if note else "")


def add_source_arguments(p: argparse.ArgumentParser, required: bool) -> None:
    p.add_argument("--source", required=required, help=f"source character mesh ({'/'.join(solver.MESH_EXTENSIONS)})")
    p.add_argument("--hair", required=required,
                   help=f"hair file of the source ({'/'.join('.' + name for name in solver.HAIR_FORMATS)})")
    p.add_argument("--prim", default=None,
                   help="USD/Alembic hair: read only the curves prim or object of this name or path (default: all)")
    p.add_argument("--source-skeleton", help="skeleton JSON of the source (default: <mesh>.skeleton.json, else glTF skin)")
    p.add_argument("--guides", type=option_type("guides"), default=None,
                   help=option_help("guides", "default 300, or every strand if fewer"))
    p.add_argument("--guides-from", metavar="ATTRIBUTE", default=None,
                   help=f"take as guides the strands this per-strand attribute flags (e.g. {solver_options.GUIDE_FLAG} of an "
                        "Unreal groom) instead of selecting --guides of them"),
    p.add_argument("--k", type=option_type("k"), default=solver.PreprocessOptions.k,
                   help=option_help("k"))
    p.add_argument("--anchoring", default=solver.PreprocessOptions.anchoring, choices=solver_options.ANCHORINGS,
                   help="anchor particles to the source's bones (Eq. 2) or to its surface (default auto: the bones "
                        "when the source has a skeleton with skin weights, else the surface)")


def add_units(p: argparse.ArgumentParser) -> None:
    """The frame options: units and axes of the inputs (every output is written back in the hair's)."""
    p.add_argument("--units", default=solver.AUTO, choices=(solver.AUTO, *solver.UNITS),
                   help="units of the hair and of meshes without a skeleton sidecar (default auto: a sidecar's, "
                        "glTF's or a .npz hair's own units, else inferred from sizes); outputs use the hair's")
    p.add_argument("--hair-units", default=None, choices=(solver.AUTO, *solver.UNITS),
                   help="units of the hair file when they differ from --units")
    p.add_argument("--up-axis", default=solver.AUTO, choices=(solver.AUTO, *solver.AXIS_CHOICES),
                   help="the axis of the input files that points up (default auto: inferred from the head bone, "
                        "the roots and the hang of the hair)")
    p.add_argument("--front-axis", default=solver.AUTO, choices=(solver.AUTO, *solver.AXIS_CHOICES),
                   help="the axis the face looks along (default auto: inferred from the face side)")


def preprocess_options(args: argparse.Namespace) -> solver.PreprocessOptions:
    if args.guides_from is not None and args.guides is not None:
        raise InputError("give --guides or --guides-from, not both", code="bad_option")
    options = solver.PreprocessOptions(k=args.k, guides=solver_options.DEFAULT_GUIDES if args.guides is None else args.guides,
                                       anchoring=args.anchoring, guides_from=args.guides_from)
    options.validate()
    return options


def mesh_limits(settings) -> dict:
    """The keyword arguments of the command line's character reads: the configured limits, the user's files."""
    return dict(max_vertices=settings.max_vertices, max_faces=settings.max_faces, max_bytes=settings.max_file_bytes,
                **LOCAL_FILES)


def mesh_units(args: argparse.Namespace, mesh: str, skeleton: str | None) -> str | None:
    # a skeleton sidecar states its own units; --units is for meshes without one
    if skeleton is not None or solver.resolve_skeleton_path(mesh) is not None:
        return None
    return None if args.units == solver.AUTO else args.units


def hair_units(args: argparse.Namespace) -> str | None:
    """The hair's units: --hair-units, else --units, else those the file records (.npz, USD), else None (inferred)."""
    given = args.hair_units if args.hair_units not in (None, solver.AUTO) else args.units
    if given not in (None, solver.AUTO):
        return given
    return solver.recorded_hair_units(args.hair)


def axes(args: argparse.Namespace) -> dict:
    return {"up": args.up_axis, "front": args.front_axis}


def add_wrap(p: argparse.ArgumentParser) -> None:
    """``--wrap``: when the source body is wrapped onto the target (:data:`hairport.solver.options.WRAP_MODES`)."""
    auto, always, off = solver_options.WRAP_MODES
    p.add_argument("--wrap", default=solver.RetargetOptions.wrap, choices=solver_options.WRAP_MODES,
                   help=f"a target whose mesh topology (vertex count, faces) is not the source's: {auto} (default) "
                        f"wraps the source body onto it first; {always} wraps a target of the source's topology "
                        f"too; {off} refuses another topology (topology_mismatch)")


def add_landmarks(p: argparse.ArgumentParser) -> None:
    """``--landmarks FILE``: named points on the source and the target that help the wrap."""
    p.add_argument("--landmarks", metavar="FILE.json",
                   help='help the wrap of a hard target: the same named points on each mesh, each in its own file\'s '
                        'coordinates: {"source": {"nose_tip": [x, y, z], "chin": [...]}, "target": {"nose_tip": [...], '
                        '"chin": [...]}} (crown, nose tip, chin, ear tops, nape: three or more also place the start)')


def landmarks_from_args(args: argparse.Namespace, adaptable: solver.AdaptableHairstyle,
                        target_input: dict) -> solver.LandmarkPairs | None:
    """The ``--landmarks`` file's pairs in hairport's frame (None without the option)."""
    if not getattr(args, "landmarks", None):
        return None
    return solver.landmarks_in_canonical(solver.read_landmarks(args.landmarks), adaptable, target_input)


@contextmanager
def target_refusals(mode: str, target: solver.Character, found: dict | None = None):
    """A target's refusals that depend on how it was read, in the command line's terms: a ``topology_mismatch``
    under ``--wrap off`` says that the default would have wrapped it; a ``wrap_failed`` names its file and the
    axes it was read in (``found``: ``canonical_target``'s report), the likeliest cause."""
    try:
        yield
    except InputError as error:
        if error.code == "topology_mismatch" and mode == solver_options.WRAP_MODES[2]:
            raise InputError(f"{error.problem}; --wrap {mode} keeps to the source's topology (--wrap "
                             f"{solver_options.WRAP_MODES[0]} wraps the source body onto this target)", error.source,
                             error.code) from None
        if error.code == "wrap_failed":
            read = "" if found is None or found["axes_how"] == "given" else (
                f" It was read with up {found['up']} and front {found['front']} ({found['axes_how']}): give "
                "--up-axis and --front-axis if those are wrong.")
            raise InputError(f"{error.problem}{read}", target.name, error.code) from None
        raise


def load_target(args: argparse.Namespace, settings, adaptable: solver.AdaptableHairstyle,
                progress=None) -> tuple[solver.Character, dict]:
    """The target of --target in hairport's frame (next to the adaptable hairstyle's source), and what was found."""
    target, units = solver.read_character(args.target, skeleton_path=args.target_skeleton,
                                          units=mesh_units(args, args.target, args.target_skeleton),
                                          **mesh_limits(settings))
    target, found = solver.canonical_target(adaptable.source, target, units=units, **axes(args))
    if progress is not None:
        note = target_note(target, found)
        if note:
            progress("input", 0.0, note)
    return target, found


def target_note(target: solver.Character, found: dict) -> str | None:
    """What reading the target found (``canonical_target``'s report), in one line; None when it holds no news
    (its own topology, in the units it states and hairport's axes)."""
    frame = f"units {found['units']} ({found['units_how']}); up {found['up']}, front {found['front']}"
    if found["topology"] == "other":
        if found["units_how"] == found["axes_how"]:  # both fitted
            frame = f"units {found['units']}, up {found['up']}, front {found['front']}"
        return (f"target: another topology than the source's ({target.n_vertices:,} vertices): {frame} "
                f"({found['axes_how']}: {found['head_fit_mm']:g} mm off on average, confidence "
                f"{found['axes_confidence']:g})")
    if found["units_how"] != "given or stated by the file" or (found["up"], found["front"]) != ("+y", "+z"):
        return f"target: {frame} ({found['axes_how']})"
    return None


def load_source(args: argparse.Namespace, settings, progress) -> solver.SourceInputs:
    """Source character and hair from --source/--hair, with the configured limits, in hairport's frame.

    Prints what was inferred (a progress line) and the warnings about the inputs (one line each)."""
    limits = solver.ReadLimits(settings.max_strands, settings.max_particles, settings.max_file_bytes,
                               memory_budget_bytes=settings.memory_budget_bytes, **LOCAL_FILES)
    progress("load", 0.0, "reading the source")
    source, source_units = solver.read_character(args.source, skeleton_path=args.source_skeleton,
                                                 units=mesh_units(args, args.source, args.source_skeleton),
                                                 **mesh_limits(settings))
    units = hair_units(args)
    hair = solver.read_hair(args.hair, units=units or "m", limits=limits, prim=args.prim)
    inputs = solver.canonical_source(source, hair, source_units=source_units, hair_units=units, **axes(args))
    progress("input", 0.0, inputs.summary())
    for note in inputs.warnings:
        print_warning(note)
    return inputs


def check_source_arguments(args: argparse.Namespace) -> None:
    if args.adaptable and (args.source or args.hair or args.source_skeleton or args.prim or args.guides is not None
                          or args.guides_from):
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
    inputs = load_source(args, settings, progress)
    began = time.perf_counter()
    adaptable = solver.preprocess(inputs.source, inputs.hair, options, progress=progress, frame=inputs.frame,
                                  input_report=inputs.report)
    return adaptable, time.perf_counter() - began
