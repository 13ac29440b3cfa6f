"""``hairport batch``: every groom onto every target character on this machine, one folder per pair and a
summary table of each pair's metrics (what ``POST /v1/batches`` does through the service).

A target of another topology than a groom's source is wrapped once per wrap key (both bodies and the part of
the source the groom's hair reaches, :func:`hairport.solver.wrap_key`) and the wrap handed to every pair with that key: a pair's
result is the one ``hairport retarget`` gives it alone, whatever else the batch holds."""

from __future__ import annotations

import argparse
import csv
import io
import sys
import time
import traceback
from dataclasses import dataclass, field, replace
from pathlib import Path

from hairport import solver
from hairport.outputs import OutputSet, add_result
from hairport.settings import get_settings
from hairport.solver import InputError
from hairport.solver import options as solver_options

from .common import (
    EXIT_BAD_INPUT,
    add_units,
    add_wrap,
    axes,
    load_source,
    mesh_limits,
    mesh_units,
    option_help,
    option_type,
    target_refusals,
)
from .solve import _DEFAULTS, add_hairline_arguments, hairline_edit

#: the summary's columns: the pair, its outcome, then the metrics every retarget reports
SUMMARY_COLUMNS = ("groom", "target", "folder", "status", "error", "seconds", "particles", "penetrating_particles",
                   "crossing_segments", "mean_segment_angle_rad", "mean_bend_error_rad", "interstrand_error_m", "root_to_target_max",
                   "wrap")
#: the summary's ``wrap`` column: the pair's target was wrapped for it, or an earlier pair's wrap was reused
#: (empty: the target has the groom's topology)
WRAPPED, REUSED = "wrapped", "reused"
#: width of the progress bar (characters)
BAR_WIDTH = 30


def add_batch(sub) -> None:
    p = sub.add_parser("batch", help="retarget every groom onto every target character (one folder per pair)")
    p.add_argument("--adaptable", nargs="+", default=[], metavar="FILE.hpa",
                   help="adaptable hairstyles from `hairport preprocess`")
    p.add_argument("--groom", nargs=2, action="append", default=[], metavar=("SOURCE", "HAIR"),
                   help="a source character mesh and its hair file, preprocessed first (repeat for more grooms)")
    p.add_argument("--targets", nargs="+", required=True, metavar="MESH",
                   help="target character meshes, of the sources' topology or of another (see --wrap; skeleton "
                        "sidecars are found)")
    p.add_argument("--out", required=True, help="folder to write <groom>__<target>/ and summary.csv/json into")
    p.add_argument("--format", default="npz", choices=solver.HAIR_FORMATS, help="format of each result (default npz)")
    p.add_argument("--guides", type=option_type("guides"), default=None,
                   help=option_help("guides", "for --groom; default 300, or every strand if fewer"))
    p.add_argument("--k", type=option_type("k"), default=solver.PreprocessOptions.k, help=option_help("k"))
    add_units(p)
    p.add_argument("--method", default=_DEFAULTS.method,
                   help=f"one of {', '.join(solver_options.METHODS)}; baselines accept the suffix +pushout "
                        f"(default: {_DEFAULTS.method})")
    p.add_argument("--max-iterations", type=option_type("max_iterations"), default=_DEFAULTS.max_iterations,
                   help=option_help("max_iterations"))
    p.add_argument("--energy-tolerance", type=option_type("energy_tolerance"), default=_DEFAULTS.energy_tolerance,
                   help=option_help("energy_tolerance"))
    p.add_argument("--spacing", type=option_type("spacing"), default=_DEFAULTS.spacing, help=option_help("spacing", f"default {_DEFAULTS.spacing:g}; {solver_options.EVEN_SPACING_WEIGHT:g} keeps "
                                                 "segments within 0.8-1.25 of their strand's stretch (docs/fidelity.md)"))
    p.add_argument("--carry", type=option_type("carry"), default=_DEFAULTS.carry,
                   help=option_help("carry", f"default {_DEFAULTS.carry:g}"))
    add_wrap(p)
    add_hairline_arguments(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(run=cmd_batch)


@dataclass
class Groom:
    name: str
    adaptable: solver.AdaptableHairstyle


@dataclass
class Known:
    """What the batch found once and every later pair reuses: each target read next to each source body (by the
    target's column and the source's :func:`hairport.solver.body_key`), and each wrap and each refused wrap (by
    its key)."""

    targets: dict[tuple[int, str], tuple[solver.Character, dict]] = field(default_factory=dict)
    wraps: dict[str, solver.WrappedTarget] = field(default_factory=dict)
    refused: dict[str, InputError] = field(default_factory=dict)

    def target(self, source: solver.Character, column: int, target: solver.Character, units: str | None,
               args: argparse.Namespace) -> tuple[solver.Character, dict]:
        """``canonical_target`` of the pair (for another topology the frame fit takes ~0.2-1 s)."""
        key = (column, solver.body_key(source.vertices, source.faces))
        if key not in self.targets:
            self.targets[key] = solver.canonical_target(source, target, units=units, **axes(args))
        return self.targets[key]


def cmd_batch(args: argparse.Namespace) -> int:
    settings = get_settings()
    if not args.adaptable and not args.groom:
        raise InputError("give at least one groom: --adaptable FILE.hpa or --groom SOURCE HAIR", code="bad_option")
    options = solver.RetargetOptions(method=args.method, max_iterations=args.max_iterations,
                                     energy_tolerance=args.energy_tolerance, spacing=args.spacing, carry=args.carry,
                                     hairline=hairline_edit(args), wrap=args.wrap)
    options.validate()
    out = Path(args.out)
    bar = ProgressBar(len(args.targets) * (len(args.adaptable) + len(args.groom)), args.quiet)
    grooms = _load_grooms(args, settings, bar)
    targets = [(Path(path).stem, solver.read_character(path, units=mesh_units(args, path, None),
                                                       **mesh_limits(settings))) for path in args.targets]
    folders = _folder_names([groom.name for groom in grooms], [name for name, _ in targets])
    rows = []
    known = Known()
    # target by target: each body's query structures are built once and reused by every groom (the
    # in-process cache of the last bodies)
    for (target_name, (target, units)), column in zip(targets, range(len(targets))):
        for groom, row in zip(grooms, range(len(grooms))):
            folder = out / folders[row][column]
            bar.start(f"{groom.name} x {target_name}")
            rows.append(_retarget_pair(groom, (column, target_name), target, units, options, args, folder, known))
            bar.finish(rows[-1]["status"] == "ok")
    rows.sort(key=lambda row: (row["groom"], row["target"]))
    with OutputSet() as outputs:
        outputs.add(out / "summary.csv", lambda path: path.write_text(_csv(rows)))
        outputs.add_json(out / "summary.json", {"pairs": rows, "format": args.format})
        outputs.commit()
    failed = [row for row in rows if row["status"] != "ok"]
    bar.close()
    print(f"{out}: {len(rows) - len(failed)} of {len(rows)} pairs retargeted; summary.csv, summary.json")
    for row in failed:
        print(f"hairport: error: {row['groom']} x {row['target']}: {row['error']}", file=sys.stderr)
    return EXIT_BAD_INPUT if failed else 0


def _load_grooms(args: argparse.Namespace, settings, bar: ProgressBar) -> list[Groom]:
    grooms = []
    for path in args.adaptable:
        bar.note(f"reading {path}")
        grooms.append(Groom(Path(path).stem, solver.load_adaptable(path)))
    options = solver.PreprocessOptions(k=args.k, guides=solver_options.DEFAULT_GUIDES if args.guides is None else args.guides)
    options.validate()
    for source_path, hair_path in args.groom:
        bar.note(f"preprocessing {hair_path}")
        # the arguments of `hairport retarget --source --hair` for this groom: read as that command reads them
        one = argparse.Namespace(**vars(args), source=source_path, hair=hair_path, source_skeleton=None, prim=None)
        inputs = load_source(one, settings, lambda *_: None)
        grooms.append(Groom(Path(hair_path).stem, solver.preprocess(inputs.source, inputs.hair, options,
                                                                     frame=inputs.frame, input_report=inputs.report)))
    return grooms


def _retarget_pair(groom: Groom, target_at: tuple[int, str], target: solver.Character, units: str | None,
                   options: solver.RetargetOptions, args: argparse.Namespace, folder: Path, known: Known) -> dict:
    """One pair (``target_at``: the target's column and name): its folder written whole (result and report), or
    its error; the summary row. ``known`` gives the pair the target already read next to its source and an earlier
    pair's wrap of the same bodies and reach, and keeps the pair's own."""
    (column, target_name), row = target_at, dict.fromkeys(SUMMARY_COLUMNS)
    row.update(groom=groom.name, target=target_name, folder=folder.name, particles=groom.adaptable.hair.n_particles)
    began = time.perf_counter()
    try:
        adaptable, frame = groom.adaptable, groom.adaptable.frame
        canonical, found = known.target(adaptable.source, column, target, units, args)
        pair_options = replace(options, hairline=solver.edit_in_canonical(frame, options.hairline))
        key = solver.wrap_key(adaptable, canonical) if solver.needs_wrap(adaptable.source, canonical, options.wrap) else None
        if key in known.refused:  # the same wrap failed for an earlier pair
            raise known.refused[key]
        wrapped = known.wraps.get(key)
        try:
            with target_refusals(options.wrap, canonical, found):
                result = solver.retarget(adaptable, canonical, pair_options, target_input=found, wrapped=wrapped)
        except InputError as error:
            if key is not None and error.code == "wrap_failed":
                known.refused[key] = error
            raise
        if result.wrapped is not None:
            known.wraps[result.wrapped.key] = result.wrapped
        report = {**result.report(), "pair": {"groom": groom.name, "target": target_name}}
        with OutputSet() as outputs:
            add_result(outputs, adaptable, result, canonical, {args.format: folder / f"result.{args.format}"},
                       report=(folder / "report.json", report))
            outputs.commit()
        metrics = result.metrics
        row.update(status="ok", **{name: metrics[name] for name in SUMMARY_COLUMNS if name in metrics})
        row["crossing_segments"] = metrics["crossing_segments"]["count"]
        row["wrap"] = None if result.wrapped is None else WRAPPED if wrapped is None else REUSED
    except InputError as error:
        row.update(status="failed", error=str(error))
    except Exception as error:  # noqa: BLE001 - one pair's crash is reported; the other pairs still run
        traceback.print_exc()
        row.update(status="failed", error=f"internal error: {type(error).__name__}: {error}")
    row["seconds"] = round(time.perf_counter() - began, 3)
    return row


def _folder_names(grooms: list[str], targets: list[str]) -> list[list[str]]:
    """``<groom>__<target>`` per pair, made unique by the pair's numbers when names repeat."""
    names = [[f"{groom}__{target}" for target in targets] for groom in grooms]
    flat = [name for row in names for name in row]
    if len(set(flat)) == len(flat):
        return names
    return [[f"{row + 1:02d}-{groom}__{column + 1:02d}-{target}" for column, target in enumerate(targets)]
            for row, groom in enumerate(grooms)]


def _csv(rows: list[dict]) -> str:
    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=SUMMARY_COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    return text.getvalue()


class ProgressBar:
    """``[#####-----] 5/12 pairs, 1 failed, 42 s  groom x target`` on stderr: redrawn in place on a terminal,
    one line per pair otherwise."""

    def __init__(self, total: int, quiet: bool):
        self.total, self.quiet = total, quiet
        self.done = self.failed = 0
        self.began = time.perf_counter()
        self.in_place = sys.stderr.isatty()

    def note(self, text: str) -> None:
        self._draw(text)

    def start(self, pair: str) -> None:
        self._draw(pair)

    def finish(self, ok: bool) -> None:
        self.done += 1
        self.failed += not ok
        self._draw("")

    def close(self) -> None:
        if not self.quiet and self.in_place:
            print(file=sys.stderr, flush=True)

    def _draw(self, text: str) -> None:
        if self.quiet:
            return
        filled = BAR_WIDTH * self.done // max(1, self.total)
        line = (f"[{'#' * filled}{'-' * (BAR_WIDTH - filled)}] {self.done}/{self.total} pairs"
                f"{f', {self.failed} failed' if self.failed else ''}, {time.perf_counter() - self.began:.0f} s  {text}")
        if self.in_place:
            print(f"\r{line:<120}", end="", file=sys.stderr, flush=True)
        elif text:
            print(line, file=sys.stderr, flush=True)
