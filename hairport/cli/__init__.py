"""The ``hairport`` command line: the parser and ``main``.

Commands live by topic: :mod:`.solve` (preprocess, retarget, hairline), :mod:`.demo`, and
:mod:`.ops` (serve, worker, warmup, purge, reindex, openapi, assets). They import the solver, the service and
the worker inside their functions on purpose: ``hairport --help`` and the light commands then
start without loading the numerical stack or the web framework.
"""

from __future__ import annotations

import argparse
import sys
import warnings

from hairport.solver import InputError

from . import batch, convert, demo, ops, solve
from .common import EXIT_BAD_INPUT, EXIT_FAILURE, StageProgress, print_warning

__all__ = ["EXIT_BAD_INPUT", "EXIT_FAILURE", "StageProgress", "build_parser", "main"]


class Parser(argparse.ArgumentParser):
    """argparse with hairport's error line: bad arguments (an option out of its range, an unknown
    flag) print one ``hairport: error:`` line and exit 2, like every other bad input."""

    def error(self, message: str):
        command = self.prog.removeprefix("hairport").strip()
        print(f"hairport: error: {command + ': ' if command else ''}{message} (see {self.prog} --help)",
              file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT)


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="hairport", description="Retarget strand hairstyles between characters.")
    sub = parser.add_subparsers(dest="command", required=True)
    solve.add_preprocess(sub)
    solve.add_retarget(sub)
    batch.add_batch(sub)
    demo.add_demo(sub)
    ops.add_assets(sub)
    ops.add_serve(sub)
    ops.add_worker(sub)
    ops.add_warmup(sub)
    ops.add_purge(sub)
    ops.add_reindex(sub)
    ops.add_db(sub)
    ops.add_migrate(sub)
    ops.add_openapi(sub)
    solve.add_hairline(sub)
    convert.add_convert(sub)
    return parser


def show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """``warnings.showwarning`` of the command line: one ``hairport: warning:`` line on stderr,
    without the Python file, line number and source line a user cannot act on."""
    print_warning(message)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as stop:  # --help (0) or a bad argument (2): returned, as every other outcome
        return stop.code if isinstance(stop.code, int) else EXIT_BAD_INPUT
    with warnings.catch_warnings():  # restores the caller's warning display when main returns
        warnings.showwarning = show_warning
        return _run(args)


def _run(args: argparse.Namespace) -> int:
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
