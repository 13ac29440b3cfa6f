"""The one progress callback of hairport: ``progress(stage, fraction, message)``.

``stage`` names the step under way (``"anchors"``, ``"solve"``, ...), ``fraction`` in
``[0, 1]`` is how far the whole operation is, ``message`` is for people. The CLI prints it,
the worker writes it to the job's record; solvers report their own fraction through
:func:`rescaled`, which places it in the caller's range.
"""

from __future__ import annotations

from collections.abc import Callable

ProgressFn = Callable[[str, float, str], None]


def no_progress(stage: str, fraction: float, message: str) -> None:
    """A :data:`ProgressFn` that reports nothing."""


def rescaled(progress: ProgressFn | None, low: float, high: float, stage: str | None = None) -> ProgressFn:
    """``progress`` seen through a sub-range: fraction ``f`` is reported as ``low + (high - low) f``
    (and under ``stage`` when given)."""
    report = progress or no_progress

    def sub(sub_stage: str, fraction: float, message: str) -> None:
        report(stage or sub_stage, low + (high - low) * fraction, message)

    return sub
