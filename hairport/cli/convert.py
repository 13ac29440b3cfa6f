"""``hairport convert IN OUT``: a hair file in another format (and units), nothing else changed.

The formats are those of the solver's registry, chosen from the extensions. The input's units
are ``--units``, else those the file records (``.npz``, a USD stage's ``metersPerUnit``), else
meters; the output is written in ``--out-units``, else the input's. What the output format
cannot hold (thickness, color) is named in a warning. Exit codes as for every command: 2 for
bad input, the output written atomically or not at all.
"""

from __future__ import annotations

import argparse

from hairport import solver

from .common import LOCAL_FILES, print_warning


def add_convert(sub) -> None:
    formats = "/".join(f".{name}" for name in solver.HAIR_FORMATS)
    p = sub.add_parser("convert", help=f"convert a hair file between formats ({formats})")
    p.add_argument("input", help="hair file to read")
    p.add_argument("output", help="hair file to write (its extension names the format)")
    p.add_argument("--units", default=solver.AUTO, choices=(solver.AUTO, *solver.UNITS),
                   help="units of the input (default: those it records, else m)")
    p.add_argument("--out-units", default=None, choices=solver.UNITS, help="units of the output (default: the input's)")
    p.add_argument("--ascii", action="store_true", help="text variant where the format has one (PLY)")
    p.add_argument("--prim", default=None, help="USD/Alembic input: only the curves prim or object of this name or path")
    p.add_argument("--quiet", action="store_true", help="no summary line")
    p.set_defaults(run=cmd_convert)


def cmd_convert(args: argparse.Namespace) -> int:
    out_format = solver.format_for_path(args.output)  # refuse an unknown output before reading
    units = args.units if args.units != solver.AUTO else (solver.recorded_hair_units(args.input) or "m")
    report = solver.read_hair_report(args.input, units=units, prim=args.prim, limits=solver.ReadLimits(**LOCAL_FILES))
    for text in report.warnings:
        print_warning(f"{args.input}: {text}")
    out_units = args.out_units or units
    solver.write_hair(args.output, report.hair, units=out_units, format=out_format, ascii=args.ascii,
                      up_axis=report.up_axis or "+y")
    if not args.quiet:
        print(f"{args.output}: {report.hair.n_strands:,} strands, {report.hair.n_particles:,} points "
              f"({report.format}, {units} -> {out_format}, {out_units})")
    return 0
