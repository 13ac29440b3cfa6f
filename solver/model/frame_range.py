"""Which frames of a target sequence to solve: ``START:END[:STEP]``, both ends included (a DCC's frame range).

A list of meshes is numbered 0, 1, ...; an animated file's frames are its time codes.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from hairport.solver.model.errors import InputError

#: most frames one sequence may have (its frames' meshes are held at once)
MAX_FRAMES = 10_000
#: ``START:END[:STEP]``, numbers (a time code may have decimals)
_RANGE = re.compile(r"^\s*(-?\d+(?:\.\d+)?)\s*:\s*(-?\d+(?:\.\d+)?)\s*(?::\s*(\d+(?:\.\d+)?)\s*)?$")


@dataclass(frozen=True)
class FrameRange:
    """Frames ``start, start + step, ...`` up to ``end`` (both ends included, as a DCC's frame range)."""

    start: float
    end: float
    step: float = 1.0

    @classmethod
    def parse(cls, text: str) -> FrameRange:
        """``"0:48"``, ``"1001:1048:2"``; ``bad_frames`` otherwise."""
        match = _RANGE.match(str(text))
        if match is None:
            raise InputError(f"frames {text!r} are not START:END[:STEP] (e.g. 0:48 or 1001:1048:2)", "frames",
                             "bad_frames")
        start, end = float(match[1]), float(match[2])
        step = float(match[3]) if match[3] is not None else 1.0
        return cls(start, end, step).checked()

    def checked(self) -> FrameRange:
        if not all(np.isfinite([self.start, self.end, self.step])) or self.step <= 0 or self.end < self.start:
            raise InputError(f"frames {self.text()}: the end must not precede the start and the step must be "
                             "positive", "frames", "bad_frames")
        if self.count() > MAX_FRAMES:
            raise InputError(f"frames {self.text()} are {self.count():,} frames, more than the {MAX_FRAMES:,} "
                             "a sequence may have", "frames", "bad_frames")
        return self

    def count(self) -> int:
        return int(np.floor((self.end - self.start) / self.step + 1e-9)) + 1

    def times(self) -> np.ndarray:
        """``(F,) float64``: the frames' numbers (time codes)."""
        return self.start + self.step * np.arange(self.count())

    def text(self) -> str:
        return f"{self.start:g}:{self.end:g}:{self.step:g}"

    def pick(self, n_items: int) -> np.ndarray:
        """``(F,) int64``: the indices of a list of ``n_items`` frames in this range (numbered from 0);
        ``bad_frames`` when the range reaches past the list or falls between its numbers."""
        times = self.times()
        if not np.allclose(times, np.round(times)):
            raise InputError(f"frames {self.text()}: a list of frames is numbered 0, 1, ...; its frames are whole "
                             "numbers", "frames", "bad_frames")
        if times[0] < 0 or times[-1] > n_items - 1:
            raise InputError(f"frames {self.text()} reach past the {n_items} frames given (numbered 0:{n_items - 1})",
                             "frames", "bad_frames")
        return np.round(times).astype(np.int64)
