"""``hairport demo``: the whole job on built-in data, no server needed.

Builds a source and a target MakeHuman character (CC0 assets, downloaded once), grows a
procedural groom on the source, retargets it with the constrained optimisation and with
every baseline, once more with a hairline edit (Sec. 6), and writes hair, report and
preview into one folder.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from hairport import solver
from hairport.outputs import OutputSet
from hairport.solver import InputError

from .common import StageProgress

#: metrics printed side by side (``a.b``: key ``b`` of metric ``a``), with their labels and formats
TABLE_ROWS = (
    ("penetrating_particles", "penetrating particles", "{:d}"),
    ("particles_below_clearance", "particles closer than eps_c", "{:d}"),
    ("min_signed_distance_m", "min signed distance (m)", "{:.2e}"),
    ("root_to_target_max", "max root error (m)", "{:.1e}"),
    ("mean_segment_angle_rad", "mean segment angle (rad)", "{:.4f}"),
    ("mean_bend_error_rad", "mean bend error (rad)", "{:.4f}"),
    ("segment_length_ratio_in_strand.p5", "segment length in strand, p5", "{:.3f}"),
    ("segment_length_ratio_in_strand.p95", "segment length in strand, p95", "{:.3f}"),
    ("interstrand_error_m", "inter-strand error (m)", "{:.2e}"),
    ("mean_distance_to_initial_m", "mean dist. to initial transfer (m)", "{:.2e}"),
    ("energy_total_per_particle", "Eq. 1 energy per particle", "{:.3e}"),
)


def add_demo(sub) -> None:
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
    p.set_defaults(run=run_demo)


def run_demo(args: argparse.Namespace) -> int:
    # the fixtures and Pillow: loaded when the demo runs, not when the command line starts
    from hairport.solver.render.preview import render_preview
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import PRESETS, build_character, write_character

    progress = StageProgress(args.quiet)
    began = time.perf_counter()
    out = Path(args.out)
    progress("characters", 0.0, f"building MakeHuman characters {args.source_preset!r} -> {args.target_preset!r}")
    for preset in (args.source_preset, args.target_preset):
        if preset not in PRESETS:
            raise InputError(f"unknown preset {preset!r}; expected one of {', '.join(PRESETS)}", code="unknown_preset")
    source = build_character(PRESETS[args.source_preset])
    target = build_character(PRESETS[args.target_preset])
    progress("groom", 0.0, f"growing a {args.style} groom: {args.strands} strands x {args.particles} particles")
    hair = generate_groom(source, args.style, args.strands, args.particles, seed=args.seed)

    adaptable = solver.preprocess(source, hair, progress=progress)
    result = solver.retarget(adaptable, target, solver.RetargetOptions(), progress=progress)
    edited = None
    if args.hairline != "none":
        edit = solver.hairline_edit(preset=args.hairline)
        edited = solver.retarget(adaptable, target, solver.RetargetOptions(hairline=edit), progress=progress)

    progress("baselines", 0.0, "running the baselines for comparison")
    baselines = {}
    for name in solver.BASELINE_METHODS:
        for method in (name, f"{name}+pushout"):
            baselines[method] = solver.retarget(adaptable, target, solver.RetargetOptions(method=method))
    admissible = {m: r for m, r in baselines.items() if r.metrics["penetrating_particles"] == 0}
    pool = admissible or baselines
    best_name = min(pool, key=lambda m: pool[m].metrics["energy_total_per_particle"])
    best = baselines[best_name]

    report = {
        "result": result.report(),
        "best_baseline": best_name,
        "baselines": {m: r.metrics for m, r in baselines.items()},
        "hairline_edit": None if edited is None else edited.report(),
        "demo": {"source_preset": args.source_preset, "target_preset": args.target_preset, "style": args.style,
                 "strands": hair.n_strands, "particles": hair.n_particles, "seed": args.seed},
    }
    with OutputSet() as outputs:
        # the character writer writes its own files atomically
        write_character(source, out / "source.obj", out / "source.skeleton.json")
        write_character(target, out / "target.obj", out / "target.skeleton.json")
        outputs.add(out / "source_hair.hair", lambda p: solver.write_hair(p, hair, format="hair"))
        outputs.add(out / "result_hair.hair", lambda p: solver.write_hair(p, result.hair, format="hair"))
        outputs.add(out / f"baseline_{best_name.replace('+', '_')}.hair",
                    lambda p: solver.write_hair(p, best.hair, format="hair"))
        panels = [
            (hair, source, None, f"source ({args.source_preset})"),
            (result.hair, target, solver.penetrating_mask(result.hair, target), f"hairport ({result.metrics['method']})"),
            (best.hair, target, solver.penetrating_mask(best.hair, target), f"best baseline: {best_name}"),
        ]
        if edited is not None:
            name = args.hairline.replace(":", "_")
            outputs.add(out / f"result_hairline_{name}.hair", lambda p: solver.write_hair(p, edited.hair, format="hair"))
            panels.append((edited.hair, target, solver.penetrating_mask(edited.hair, target),
                           f"hairline {args.hairline}"))
        outputs.add_json(out / "report.json", report)
        outputs.add(out / "preview.png", lambda p: render_preview(p, panels))
        outputs.commit()

    print(format_table(result.metrics, best.metrics, best_name))
    if edited is not None:
        h = edited.metrics["hairline"]
        print(f"\nhairline {h['edit']}: {h['roots_moved']} roots moved (largest {100 * h['max_travel_m']:.1f} cm) in "
              f"{h['seconds']:.2f} s, root density change L1 {h['density_change_l1']:.3f}, penetrating particles "
              f"{edited.metrics['penetrating_particles']}")
    print(f"\nwrote {out}/ (result_hair.hair, report.json, preview.png, characters) in "
          f"{time.perf_counter() - began:.1f} s", file=sys.stdout)
    return 0


def format_table(ours: dict, baseline: dict, baseline_name: str) -> str:
    """The metric table printed by the demo: ours next to the best baseline."""
    width = max(len(label) for _, label, _ in TABLE_ROWS)
    head = f"{'metric':<{width}}  {'hairport':>12}  {baseline_name:>22}"
    lines = [head, "-" * len(head)]
    for key, label, fmt in TABLE_ROWS:
        lines.append(f"{label:<{width}}  {fmt.format(_metric(ours, key)):>12}  {fmt.format(_metric(baseline, key)):>22}")
    return "\n".join(lines)


def _metric(metrics: dict, key: str):
    """``metrics[key]``, or ``metrics[a][b]`` for ``key = "a.b"``."""
    value = metrics
    for part in key.split("."):
        value = value[part]
    return value
