"""All-or-nothing output files: everything is written to temporary names first and renamed
into place only when every file succeeded, so a failed run leaves no partial output. A retarget's
result goes out one way (:func:`add_result`), whoever writes it: ``hairport retarget``, ``hairport
batch`` and the worker.

Every output gets one file mode, the solver's ``FILE_MODE`` less the umask (0644 under the
usual umask 022): the temporary file is created with it, and writers that write into it (the
report, the preview) keep it, as does the atomic write that replaces it (the hair, the artifact).
"""

from __future__ import annotations

import json
import os
import re
import secrets
from collections.abc import Callable, Mapping
from pathlib import Path

import numpy as np

from hairport import solver
from hairport.solver import FILE_MODE
from hairport.solver import sequence as solver_sequence

#: random bytes in a temporary output's name (hex-encoded: twice as many characters)
TEMP_NAME_BYTES = 6


class OutputSet:
    """Collect output files, then :meth:`commit` them together (or :meth:`abort`)."""

    def __init__(self) -> None:
        self._pending: list[tuple[Path, Path]] = []

    def add(self, final: str | os.PathLike, write: Callable[[Path], None]) -> None:
        """Write ``final`` through ``write(temporary_path)``; the file appears only on commit."""
        final = Path(final)
        final.parent.mkdir(parents=True, exist_ok=True)
        temporary = _create_temporary(final)
        self._pending.append((temporary, final))
        write(temporary)

    def add_json(self, final: str | os.PathLike, document: dict) -> None:
        self.add(final, lambda path: path.write_text(json.dumps(document, indent=2, default=json_default) + "\n"))

    def commit(self) -> list[Path]:
        for temporary, final in self._pending:
            os.replace(temporary, final)
        done = [final for _, final in self._pending]
        self._pending.clear()
        return done

    def abort(self) -> None:
        for temporary, _ in self._pending:
            temporary.unlink(missing_ok=True)
        self._pending.clear()

    def __enter__(self) -> "OutputSet":
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            self.abort()


def add_result(outputs: OutputSet, adaptable: solver.AdaptableHairstyle, result: solver.RetargetResult,
               target: solver.Character, hair: Mapping[str, str | os.PathLike], *,
               report: tuple[str | os.PathLike, dict] | None = None, preview: str | os.PathLike | None = None,
               flag_guides: bool = False) -> None:
    """Add a retarget's result to ``outputs`` in the groom's frame: its hair, then its report and preview.

    The hair is written in the units and axes the groom was read in (``adaptable.frame``), as the
    input was; the report and the preview are the solver's (hairport's frame, meters).

    Parameters
    ----------
    outputs : OutputSet
        Committed by the caller.
    adaptable : AdaptableHairstyle
        The hairstyle the result was retargeted from (its frame, guides and source).
    result : RetargetResult
    target : Character
        The target the result was retargeted onto (for the preview).
    hair : mapping of str to path-like
        One hair file per format name (:data:`hairport.solver.HAIR_FORMATS`), e.g. ``{"npz": "out/result.npz"}``.
    report : (path-like, dict), optional
        Where to write the report, and the report (JSON; numpy values as numbers and lists).
    preview : path-like, optional
        Where to write the PNG preview (source against result; Pillow, imported only then).
    flag_guides : bool
        Write the guides the solve used as the per-strand attribute :data:`hairport.solver_options.GUIDE_FLAG`.
    """
    frame = adaptable.frame
    in_frame = hair_as_written(adaptable, result, flag_guides)
    for name, final in hair.items():
        outputs.add(final, lambda path, name=name: solver.write_hair(path, in_frame, units=frame.units, format=name,
                                                                     up_axis=frame.up))
    if report is not None:
        outputs.add_json(*report)
    if preview is not None:
        from hairport.solver.render.preview import write_result_preview

        outputs.add(preview, lambda path: write_result_preview(path, adaptable, result, target))


def hair_as_written(adaptable: solver.AdaptableHairstyle, result: solver.RetargetResult,
                    flag_guides: bool = False) -> solver.Hair:
    """A result's hair as its files hold it: in the groom's axes (meters), with the guides flagged when asked."""
    strands = solver.with_guide_flags(result.hair, adaptable.multiscale.guides) if flag_guides else result.hair
    return solver.hair_in_frame(adaptable.frame, strands)


#: the run of ``#`` in a per-frame file name that each frame's number replaces (zero-padded to the run's length)
FRAME_NUMBER = re.compile(r"#+")


def frame_path(pattern: str | os.PathLike, time: float) -> Path:
    """``hair.####.abc`` at frame 12 is ``hair.0012.abc``; a time code between frames keeps its decimals."""
    text = os.fspath(pattern)
    run = FRAME_NUMBER.search(text)
    if run is None:
        raise ValueError(f"{text} has no #### for the frame number")
    width = run.end() - run.start()
    number = f"{int(round(time)):0{width}d}" if float(time).is_integer() else f"{time:0{width}g}"
    return Path(text[:run.start()] + number + text[run.end():])


class SequenceOutputs:
    """Where a sequence's results go: one animated hair file (a format of ``solver_sequence.ANIMATED_FORMATS``) or one
    file per frame (a name with ``####``), per-frame previews (a name with ``####``), and one report.

    Refuses a plan it cannot carry out before any frame is solved (``bad_option``, ``unknown_format``)."""

    def __init__(self, out: str | os.PathLike, preview: str | os.PathLike | None = None,
                 report: str | os.PathLike | None = None) -> None:
        self.out, self.preview, self.report = os.fspath(out), preview, report
        self.per_frame = FRAME_NUMBER.search(self.out) is not None
        self.format = solver.format_for_path(self.out)
        if not self.per_frame and self.format not in solver_sequence.ANIMATED_FORMATS:
            animated = ", ".join(solver_sequence.ANIMATED_FORMATS)
            raise solver.InputError(
                f"a sequence is written as one animated file ({animated}) or one file per frame (a name with #### for "
                f"the frame number, e.g. hair.####.{self.format}); {self.out} is neither", self.out, "bad_option")
        if preview is not None and FRAME_NUMBER.search(os.fspath(preview)) is None:
            raise solver.InputError(f"a sequence's previews are one per frame: give a name with #### for the frame "
                                    f"number (e.g. preview.####.png), not {os.fspath(preview)}", os.fspath(preview),
                                    "bad_option")
        self._layout: solver.Hair | None = None
        self._points: list[np.ndarray] = []
        self._times: list[float] = []

    def add_frame(self, outputs: OutputSet, adaptable: solver.AdaptableHairstyle, result: solver.RetargetResult,
                  target: solver.Character, time: float, flag_guides: bool = False) -> None:
        """One frame's result: its file and preview written now (committed with ``outputs``), its points kept for the
        animated file."""
        frame_files = {self.format: frame_path(self.out, time)} if self.per_frame else {}
        add_result(outputs, adaptable, result, target, frame_files,
                   preview=None if self.preview is None else frame_path(self.preview, time), flag_guides=flag_guides)
        if not self.per_frame:
            in_frame = hair_as_written(adaptable, result, flag_guides)
            if self._layout is None:
                self._layout = in_frame
            # float32, as the animated formats write them: half the memory of a long sequence
            self._points.append(in_frame.points.astype(np.float32))
            self._times.append(float(time))

    def finish(self, outputs: OutputSet, adaptable: solver.AdaptableHairstyle, report: dict,
               frames_per_second: float = solver_sequence.FRAMES_PER_SECOND) -> None:
        """The animated file (every frame's points) and the report."""
        if not self.per_frame and self._layout is not None:
            animation = solver_sequence.Animation(np.array(self._times), self._points, frames_per_second)
            frame, layout = adaptable.frame, self._layout
            outputs.add(self.out, lambda path: solver_sequence.write_hair_frames(
                path, layout, animation, units=frame.units, format=self.format, up_axis=frame.up))
        if self.report is not None:
            outputs.add_json(self.report, report)


def _create_temporary(final: Path) -> Path:
    """A new empty file beside ``final`` with the mode every output has (not mkstemp's 0600)."""
    while True:
        # the temporary name keeps the extension, so writers that infer the format from it still work
        temporary = final.parent / f".{final.stem}.{secrets.token_hex(TEMP_NAME_BYTES)}.part{final.suffix}"
        try:
            os.close(os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0), FILE_MODE))
            return temporary
        except FileExistsError:
            continue


def json_default(value):
    """``json.dumps`` fallback for numpy scalars and arrays."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
