"""``hairport retarget`` onto a sequence: several --target meshes, or --frames of one animated target (a USD stage's
time-sampled points, a glTF's morph targets, an Alembic mesh)."""

from __future__ import annotations

import argparse
from dataclasses import replace

from hairport import solver
from hairport.outputs import OutputSet, SequenceOutputs
from hairport.settings import get_settings
from hairport.solver import InputError
from hairport.solver import sequence as solver_sequence

from .common import (
    StageProgress,
    adaptable_from_args,
    axes,
    landmarks_from_args,
    mesh_limits,
    mesh_units,
    target_note,
    target_refusals,
)


def cmd_retarget_sequence(args: argparse.Namespace, options: solver.RetargetOptions) -> int:
    """Retarget onto every frame in order (``sequence.retarget_sequence``) and write the frames as one animated file or
    one file per frame, previews per frame, and one report."""
    settings = get_settings()
    progress = StageProgress(args.quiet)
    if args.landmarks is not None:
        raise InputError("--landmarks name points of one target: a sequence's frames move them", code="bad_option")
    if args.target_skeleton is not None:
        raise InputError("--target-skeleton names one target's skeleton: a sequence's meshes each take their own "
                         "sidecar (<mesh>.skeleton.json), an animated stage's frames the source's rig",
                         code="bad_option")
    sequence = solver_sequence.SequenceOptions(warm=args.warm_start, temporal=args.temporal)
    sequence.validate()
    frames = solver_sequence.FrameRange.parse(args.frames) if args.frames is not None else None
    plan = SequenceOutputs(args.out, args.preview, args.report)  # refused before any work
    adaptable, preprocess_seconds = adaptable_from_args(args, settings, progress)
    progress("load", 0.0, f"reading the target sequence ({len(args.target)} file{'s' if len(args.target) > 1 else ''})")
    weights = None if args.morph_weights is None else solver_sequence.read_morph_weights(args.morph_weights)
    read = solver_sequence.read_character_frames(args.target, frames, units=mesh_units(args, args.target[0], None),
                                                 morph_weights=weights, **mesh_limits(settings))
    bodies, times = read.characters, read.times
    bodies, found = solver_sequence.canonical_sequence(adaptable.source, bodies, units=read.units, **axes(args))
    note = target_note(bodies[0], found)
    if note:
        progress("input", 0.0, note)
    options = replace(options, hairline=solver.edit_in_canonical(adaptable.frame, options.hairline),
                      landmarks=landmarks_from_args(args, adaptable, found))
    options.validate()
    results = []
    with OutputSet() as outputs, target_refusals(options.wrap, bodies[0], found):
        solved = solver_sequence.retarget_sequence(adaptable, bodies, options, sequence, progress=progress,
                                                   target_input=found)
        for result, body, time in zip(solved, bodies, times, strict=True):
            plan.add_frame(outputs, adaptable, result, body, time, flag_guides=args.flag_guides)
            results.append(solver_sequence.FrameRecord.of(result))
        report = solver_sequence.sequence_report(results, times)
        report["timings_s"] = {"preprocess": preprocess_seconds}
        report["inputs"] = {"target": list(args.target), "frames": None if frames is None else frames.text(),
                            "strands": adaptable.hair.n_strands, "particles": adaptable.hair.n_particles,
                            "units": adaptable.frame.units, "warm_start": sequence.warm, "temporal": sequence.temporal}
        plan.finish(outputs, adaptable, report, read.frames_per_second)
        written = outputs.commit()
    summary = report["summary"]
    progress("done", 1.0, f"wrote {_listed(written)}")
    later = summary["later_frames_median_s"]
    print(f"{summary['frames']} frames: penetrating particles at most {summary['penetrating_particles_max']}, largest "
          f"jump between frames {1e3 * summary['largest_jump_m']:.1f} mm, {summary['frames_that_pop']} frames pop; "
          f"first frame {summary['first_frame_s']:.1f} s" + ("" if later is None else f", later ones {later:.1f} s "
                                                               "(median)"))
    return 0


def _listed(paths: list) -> str:
    return ", ".join(map(str, paths)) if len(paths) <= 4 else f"{len(paths)} files ({paths[0]} ... {paths[-1]})"
