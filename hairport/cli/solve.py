"""``hairport preprocess``, ``hairport retarget`` and ``hairport hairline``: the solver on files."""

from __future__ import annotations

import argparse
from dataclasses import replace

from hairport import solver
from hairport.outputs import OutputSet, add_result
from hairport.settings import get_settings
from hairport.solver import InputError, documents
from hairport.solver import options as solver_options
from hairport.solver import sequence as solver_sequence

from .common import (
    StageProgress,
    adaptable_from_args,
    add_landmarks,
    add_source_arguments,
    add_units,
    add_wrap,
    check_source_arguments,
    landmarks_from_args,
    load_source,
    load_target,
    option_help,
    option_type,
    preprocess_options,
    target_refusals,
)
from .sequence import cmd_retarget_sequence

_DEFAULTS = solver.RetargetOptions()


def add_preprocess(sub) -> None:
    p = sub.add_parser("preprocess", help="compute the adaptable hairstyle of a source groom once (.hpa)")
    add_source_arguments(p, required=True)
    p.add_argument("--out", required=True, help=f"artifact file to write (extension {solver.ARTIFACT_EXTENSION})")
    add_units(p)
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(run=cmd_preprocess)


def add_retarget(sub) -> None:
    p = sub.add_parser("retarget", help="retarget a hairstyle from a source to a target character")
    p.add_argument("--adaptable", help="adaptable hairstyle from `hairport preprocess` (instead of --source/--hair)")
    add_source_arguments(p, required=False)
    p.add_argument("--target", required=True, nargs="+", metavar="MESH",
                   help="target character mesh: of the source's topology, or of another (see --wrap); several meshes "
                        "(one topology) are the frames of a sequence, retargeted in order, each from the one before")
    p.add_argument("--frames", metavar="START:END[:STEP]",
                   help="retarget a sequence: these frames (both ends included) of an animated USD target (time "
                        "codes of its time-sampled mesh points), or of the --target meshes (numbered from 0)")
    p.add_argument("--morph-weights", metavar="FILE.json",
                   help="a glTF target's morph-target weights of each frame ([[w1, w2, ...], ...], frames numbered "
                        "from 0) instead of its animation")
    p.add_argument("--temporal", type=option_type("temporal"), default=solver_sequence.SequenceOptions.temporal,
                   help=option_help("temporal", "sequences only; 1e4-1e5 holds each frame to the one before"))
    p.add_argument("--no-warm-start", dest="warm_start", action="store_false",
                   help="solve every frame of a sequence cold, from its own initial transfer")
    p.add_argument("--out", required=True,
                   help="output hair file; the format follows the extension. A sequence: one animated file "
                        f"({', '.join(solver_sequence.ANIMATED_FORMATS)}) or one file per frame (a name with #### for "
                        "the frame number, e.g. hair.####.npz)")
    p.add_argument("--target-skeleton", help="skeleton JSON of the target (default: sidecar, glTF skin, else transferred)")
    p.add_argument("--method", default=_DEFAULTS.method,
                   help=f"one of {', '.join(solver_options.METHODS)}; baselines accept the suffix +pushout "
                        f"(default: {_DEFAULTS.method})")
    p.add_argument("--report", help="write metrics and per-stage timings as JSON here")
    p.add_argument("--preview", help="write a PNG preview (source vs result, penetrating particles in red); a "
                                     "sequence: one per frame, a name with #### (e.g. preview.####.png)")
    p.add_argument("--flag-guides", action="store_true",
                   help=f"write the guides the solve used as the per-strand attribute {solver_options.GUIDE_FLAG} "
                        "(1 guide, 0 other; Unreal's convention)")
    add_units(p)
    p.add_argument("--alpha", type=option_type("alpha"), default=_DEFAULTS.alpha, help=option_help("alpha"))
    p.add_argument("--beta", type=option_type("beta"), default=_DEFAULTS.beta, help=option_help("beta"))
    p.add_argument("--spacing", type=option_type("spacing"), default=None, help=option_help("spacing", f"default {_DEFAULTS.spacing:g}, {solver_options.SEQUENCE_SPACING:g} for a sequence; "
                                                 f"{solver_options.EVEN_SPACING_WEIGHT:g} keeps segments within 0.8-1.25 of their strand's stretch "
                                                 "(docs/fidelity.md)"))
    p.add_argument("--carry", type=option_type("carry"), default=_DEFAULTS.carry,
                   help=option_help("carry", f"default {_DEFAULTS.carry:g}"))
    p.add_argument("--eps-c", type=option_type("eps_c"), default=_DEFAULTS.eps_c, help=option_help("eps_c"))
    p.add_argument("--max-iterations", type=option_type("max_iterations"), default=_DEFAULTS.max_iterations, help=option_help("max_iterations"))
    p.add_argument("--energy-tolerance", type=option_type("energy_tolerance"), default=_DEFAULTS.energy_tolerance,
                   help=option_help("energy_tolerance", "0 runs every strand to the step tolerance or the cap"))
    p.add_argument("--workers", type=option_type("workers"), default=None, help=option_help("workers", "default: 1, this process on its threads"))
    p.add_argument("--qp-backend", default=_DEFAULTS.qp_backend, choices=solver_options.QP_BACKENDS,
                   help=f"solver of the coupled QPs (default {_DEFAULTS.qp_backend})")
    add_wrap(p)
    add_landmarks(p)
    add_hairline_arguments(p)
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(run=cmd_retarget)


def add_hairline_arguments(p: argparse.ArgumentParser) -> None:
    edit = p.add_mutually_exclusive_group()
    edit.add_argument("--hairline", metavar="PRESET[:AMOUNT]",
                      help=f"edit the front hairline: one of {', '.join(solver_options.HAIRLINE_PRESETS)}, "
                           "amount in [0, 1] (default 1)")
    edit.add_argument("--hairline-curve", metavar="FILE.json",
                      help='edit the front hairline to a drawn curve: {"units": "m", "points": [[x, y, z], ...], '
                           '"turning_points": [i, ...]} (see `hairport hairline`)')
    p.add_argument("--hairline-method", default=solver.HairlineEdit.method, choices=solver_options.RELOCATION_METHODS,
                   help="how the roots follow the hairline: the embedded membrane (default) or a baseline")
    p.add_argument("--parameterization", default=solver.HairlineEdit.parameterization,
                   choices=solver_options.PARAMETERIZATIONS,
                   help=f"head parameterization the scalp moves in (default {solver.HairlineEdit.parameterization})")


def add_hairline(sub) -> None:
    p = sub.add_parser("hairline", help="write a target's current front hairline (or a preset's edit) as curve JSON")
    p.add_argument("--adaptable", help="adaptable hairstyle from `hairport preprocess` (instead of --source/--hair)")
    add_source_arguments(p, required=False)
    p.add_argument("--target", required=True,
                   help="target character mesh: of the source's topology, or of another (see --wrap)")
    p.add_argument("--target-skeleton", help="skeleton JSON of the target")
    p.add_argument("--preset", metavar="PRESET[:AMOUNT]", help="write this preset's edit instead of the current hairline")
    p.add_argument("--out", required=True, help="curve JSON to write")
    add_units(p)
    add_wrap(p)
    add_landmarks(p)
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(run=cmd_hairline)


def hairline_edit(args: argparse.Namespace) -> solver.HairlineEdit | None:
    if args.hairline is None and args.hairline_curve is None:
        return None
    return solver.hairline_edit(preset=args.hairline, curve_path=args.hairline_curve,
                                method=args.hairline_method, parameterization=args.parameterization)


def cmd_preprocess(args: argparse.Namespace) -> int:
    settings = get_settings()
    progress = StageProgress(args.quiet)
    if not args.out.endswith(solver.ARTIFACT_EXTENSION):
        raise InputError(f"the artifact file must end in {solver.ARTIFACT_EXTENSION}", args.out, "unknown_format")
    solver.format_for_path(args.hair)
    options = preprocess_options(args)
    inputs = load_source(args, settings, progress)
    hair = inputs.hair
    adaptable = solver.preprocess(inputs.source, hair, options, progress=progress, frame=inputs.frame,
                                  input_report=inputs.report)
    with OutputSet() as outputs:
        outputs.add(args.out, lambda path: solver.save_adaptable(adaptable, path))
        outputs.commit()
    print(f"{args.out}: {hair.n_strands} strands, {hair.n_particles} particles, "
          f"{len(adaptable.multiscale.guides)} guides")
    return 0


def cmd_retarget(args: argparse.Namespace) -> int:
    if len(args.target) > 1 or args.frames is not None or args.morph_weights is not None:
        return cmd_retarget_sequence(args, retarget_options(args, solver_options.SEQUENCE_SPACING))
    if args.temporal or not args.warm_start:
        raise InputError("--temporal and --no-warm-start apply to a sequence (several --target meshes, or --frames)",
                         code="bad_option")
    args.target = args.target[0]
    settings = get_settings()
    progress = StageProgress(args.quiet)
    check_source_arguments(args)
    out_format = solver.format_for_path(args.out)  # refuse unknown formats and options before any work
    if args.hair:
        solver.format_for_path(args.hair)
    options = retarget_options(args)
    adaptable, preprocess_seconds = adaptable_from_args(args, settings, progress)
    inputs = {"adaptable": args.adaptable} if args.adaptable else {"source": args.source, "hair": args.hair}
    target, target_input = load_target(args, settings, adaptable, progress)
    # a drawn hairline is in the groom's axes, like every output; landmarks in each mesh's own
    options = replace(options, hairline=solver.edit_in_canonical(adaptable.frame, options.hairline),
                      landmarks=landmarks_from_args(args, adaptable, target_input))
    options.validate()
    with target_refusals(options.wrap, target, target_input):
        result = solver.retarget(adaptable, target, options, progress=progress, target_input=target_input)
    hair = adaptable.hair
    report = result.report()
    report["timings_s"] = {"preprocess": preprocess_seconds, **report["timings_s"]}
    report["inputs"] = {**inputs, "target": args.target, "strands": hair.n_strands, "particles": hair.n_particles,
                        "guides": len(adaptable.multiscale.guides), "units": adaptable.frame.units}
    with OutputSet() as outputs:
        add_result(outputs, adaptable, result, target, {out_format: args.out},
                   report=(args.report, report) if args.report else None, preview=args.preview or None,
                   flag_guides=args.flag_guides)
        written = outputs.commit()
    m = result.metrics
    progress("done", 1.0, f"wrote {', '.join(str(p) for p in written)}")
    print(f"penetrating particles {m['penetrating_particles']}, mean segment angle "
          f"{m['mean_segment_angle_rad']:.4f} rad, inter-strand error {m['interstrand_error_m']:.2e} m, "
          f"max root error {m['root_to_target_max']:.1e} m")
    if "wrap" in m:
        print(wrap_line(m["wrap"]))
    if "hairline" in m:
        h = m["hairline"]
        print(f"hairline {h['edit']} ({h['method']}): {h['roots_moved']} roots moved (largest "
              f"{100 * h['max_travel_m']:.2f} cm), density change L1 {h['density_change_l1']:.3f} "
              f"Linf {h['density_change_linf']:.3f}, relocation {h['seconds']:.2f} s")
    return 0


def retarget_options(args: argparse.Namespace, spacing: float = _DEFAULTS.spacing) -> solver.RetargetOptions:
    """The retarget's options from the command line, checked (the hairline in the groom's axes, landmarks not yet);
    ``spacing`` when ``--spacing`` is not given."""
    spacing = spacing if args.spacing is None else args.spacing
    options = solver.RetargetOptions(method=args.method, alpha=args.alpha, beta=args.beta, spacing=spacing,
                                     carry=args.carry, eps_c=args.eps_c, max_iterations=args.max_iterations,
                                     energy_tolerance=args.energy_tolerance, workers=args.workers,
                                     qp_backend=args.qp_backend, hairline=hairline_edit(args), wrap=args.wrap)
    options.validate()
    return options


def wrap_line(report: dict) -> str:
    """One line of a wrap's report (the metrics' ``wrap``, meters)."""
    residual = report["residual_m"]
    return (f"wrapped the source body onto the target: residual mean {1e3 * residual['mean']:.2f} mm, p95 "
            f"{1e3 * residual['p95']:.2f} mm over {report['fitted_vertices']:,} source vertices, coverage "
            f"{report['coverage']:.0%}, {report['iterations']} iterations, {report['seconds']:.1f} s")


def cmd_hairline(args: argparse.Namespace) -> int:
    settings = get_settings()
    progress = StageProgress(args.quiet)
    adaptable, _ = adaptable_from_args(args, settings, progress)
    target, found = load_target(args, settings, adaptable, progress)
    landmarks = landmarks_from_args(args, adaptable, found)
    solver.RetargetOptions(wrap=args.wrap, landmarks=landmarks).validate()
    with target_refusals(args.wrap, target, found):
        if solver.needs_wrap(adaptable.source, target, args.wrap):
            # the hairline lies on the source's scalp: on another topology, on the source body wrapped onto it
            progress("wrap", 0.0, f"wrapping the source body onto the target ({target.n_vertices:,} vertices)")
            target = solver.wrap_target(adaptable, target, landmarks=landmarks).shape
        else:
            solver.require_a_wrap_for(landmarks, args.wrap)
        # written in the groom's axes and units, as the result of a retarget (and read back so)
        document = documents.curve_document_in_frame(adaptable.frame, documents.hairline_document(
            adaptable, target, args.preset))
    with OutputSet() as outputs:
        outputs.add_json(args.out, document)
        outputs.commit()
    print(f"{args.out}: front hairline of {len(document['points'])} points, turning points "
          f"{document['turning_points']}")
    return 0
