"""One hairstyle onto a sequence of bodies: morph sweeps and animated characters, frame by frame.

The frames share one mesh topology (their own; the source's may differ, as for any target). Each
frame is a retarget (:func:`~hairport.solver.pipeline.retarget`) of its own, but for the solvers
it starts where the previous frame ended: the previous result moved as the body moved from that
frame to this one (the difference of the two frames' initial transfers,
:class:`~hairport.solver.pipeline.PreviousFrame`), so a sequence of close bodies costs less per
frame than a cold retarget and lands in the same valley from frame to frame. The optional
temporal term (:class:`~hairport.solver.options.SequenceOptions`) also anchors each particle to
that moved result, for sequences that must not flicker.

Frames of another topology than the source's are wrapped once, on the first frame; the later frames carry that
wrap on their surface (:class:`~hairport.solver.wrapping.EmbeddedWrap`): one correspondence for the whole sequence,
and no wrap's seconds per frame.

Coherence, per frame after the first: the largest particle jump from the previous frame, beside
the body's largest motion near the hair (vertices in the cells of :data:`NEAR_HAIR_M` that hold
hair or touch one that does). A frame whose jump exceeds ``JUMP_MOTION_FACTOR`` times that motion
plus :data:`JUMP_ALLOWANCE_M` pops.

Convention: meters, hairport's frame (Y up, face +Z), as every solver module.

A public module of the solver (``from hairport.solver import sequence``): besides the sequence's solve and report,
it hands out what reading and writing a sequence takes (frame ranges, the frames of a target, animated hair files).
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from hairport.solver.adaptable import AdaptableHairstyle
from hairport.solver.inputs import canonical_sequence as canonical_sequence
from hairport.solver.io.character.frames import MAX_SEQUENCE_VERTICES as MAX_SEQUENCE_VERTICES
from hairport.solver.io.character.frames import TargetFrames as TargetFrames
from hairport.solver.io.character.frames import check_total_vertices as check_total_vertices
from hairport.solver.io.character.frames import read_character_frames as read_character_frames
from hairport.solver.io.character.frames import read_morph_weights as read_morph_weights
from hairport.solver.io.hair import ANIMATED_FORMATS as ANIMATED_FORMATS
from hairport.solver.io.hair import write_hair_frames as write_hair_frames
from hairport.solver.io.hair.common import FRAMES_PER_SECOND as FRAMES_PER_SECOND
from hairport.solver.io.hair.common import Animation as Animation
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError
from hairport.solver.model.frame import InputFrame
from hairport.solver.model.frame_range import MAX_FRAMES as MAX_FRAMES
from hairport.solver.model.frame_range import FrameRange as FrameRange
from hairport.solver.model.hair import Hair
from hairport.solver.model.progress import ProgressFn, no_progress, rescaled
from hairport.solver.options import SOLVER_METHODS, RetargetOptions
from hairport.solver.options import SequenceOptions as SequenceOptions
from hairport.solver.pipeline import RetargetResult, retarget
from hairport.solver.wrapping import EmbeddedWrap

#: the cell size of "near the hair" (m): a vertex within this of a particle is near it (and some up to
#: twice the cells' diagonal away)
NEAR_HAIR_M = 0.05
#: a frame pops when its largest particle jump exceeds this times the body's largest motion near the hair ...
JUMP_MOTION_FACTOR = 2.0
#: ... plus this (m)
JUMP_ALLOWANCE_M = 1e-3
def require_one_topology(frames: Sequence[Character]) -> None:
    """Refuse (``sequence_topology``) frames that are not one mesh: the same vertex count and faces as frame 0."""
    if not frames:
        raise InputError("the target sequence has no frames", "frames", "bad_frames")
    first = frames[0]
    for number, frame in enumerate(frames[1:], start=1):
        if frame.n_vertices != first.n_vertices or not np.array_equal(frame.faces, first.faces):
            raise InputError(f"frame {number} ({frame.name}) has {frame.n_vertices:,} vertices and "
                             f"{len(frame.faces):,} faces, frame 0 ({first.name}) {first.n_vertices:,} and "
                             f"{len(first.faces):,}: the frames of a sequence must be one mesh", frame.name,
                             "sequence_topology")


def check_sequence_options(sequence: SequenceOptions, method: str) -> None:
    """Refuse (``bad_option``) sequence options out of range or that the retarget ``method`` cannot take: a
    temporal term with a baseline, which solves nothing."""
    sequence.validate()
    if sequence.temporal and method not in SOLVER_METHODS:
        raise InputError(f"option temporal pulls a solve toward the previous frame; the baseline {method} "
                         "solves nothing (it retargets each frame on its own)", code="bad_option")


def retarget_sequence(
    adaptable: AdaptableHairstyle,
    frames: Sequence[Character],
    options: RetargetOptions = RetargetOptions(),
    sequence: SequenceOptions = SequenceOptions(),
    progress: ProgressFn | None = None,
    should_stop: Callable[[], bool] | None = None,
    frame_arguments: Callable[[int, Character], dict] | None = None,
    **retarget_arguments,
) -> Iterator[RetargetResult]:
    """Retarget the hairstyle onto every frame in order, each warm from the one before (module notes).

    Parameters
    ----------
    adaptable : AdaptableHairstyle
    frames : sequence of Character
        Canonical frame, one topology (:func:`require_one_topology`).
    options : RetargetOptions
        Every frame's (a baseline method retargets each frame on its own: it has no solve to start warm).
    sequence : SequenceOptions
    progress : callable(stage, fraction, message), optional
        Frame ``i`` of ``F`` reports in ``[i / F, (i + 1) / F]``, its stages named ``frame i: stage``.
    should_stop : callable() -> bool, optional
    frame_arguments : callable(number, body) -> dict, optional
        More arguments of one frame's :func:`~hairport.solver.pipeline.retarget` (its ``collision_surface`` from a
        cache, ...), called just before the frame is solved.
    retarget_arguments
        Passed to every frame's :func:`~hairport.solver.pipeline.retarget` (``fine_runner``, ...).

    Yields
    ------
    result : RetargetResult
        One per frame, in order; ``result.metrics["coherence"]`` from the second on (:func:`frame_coherence`),
        ``result.timings["frame"]`` the frame's seconds.
    """
    options.validate()
    check_sequence_options(sequence, options.method)
    require_one_topology(frames)
    progress = progress or no_progress
    previous: RetargetResult | None = None
    wrap: EmbeddedWrap | None = None
    for number, body in enumerate(frames):
        frame_progress = _numbered(rescaled(progress, number / len(frames), (number + 1) / len(frames)), number)
        carry = previous.as_previous() if previous is not None and sequence.warm else None
        if previous is not None:
            previous.queries = None  # handed on in the carry: a caller's list of frames does not hold every body's
        began = time.perf_counter()
        own = frame_arguments(number, body) if frame_arguments is not None else {}
        if wrap is not None:
            own = {**own, "wrapped": wrap.on(body)}
        result = retarget(adaptable, body, options, progress=frame_progress, should_stop=should_stop,
                          previous=carry, temporal=sequence.temporal, keep_queries=True, **retarget_arguments, **own)
        if number == 0 and result.wrapped is not None:
            wrap = EmbeddedWrap.of(result.wrapped, body)
        if previous is not None:
            result.metrics["coherence"] = frame_coherence(previous.hair.points, result.hair.points,
                                                          frames[number - 1].vertices, body.vertices)
        result.metrics["frame"] = number
        result.timings["frame"] = time.perf_counter() - began
        yield result
        previous = result
    if previous is not None:
        previous.queries = None


def _numbered(progress: ProgressFn, number: int) -> ProgressFn:
    def report(stage: str, fraction: float, message: str) -> None:
        progress(f"frame {number}: {stage}", fraction, message)

    return report


def body_motion_near_hair(points: np.ndarray, before: np.ndarray, after: np.ndarray,
                          reach: float = NEAR_HAIR_M) -> float:
    """The body's largest vertex motion near the hair (m).

    Parameters
    ----------
    points : (N, 3) float64
        The hair.
    before, after : (V, 3) float64
        The body's vertices in two frames.
    reach : float
        Cell size (m): vertices in a cell that holds a particle, or in one of its 26 neighbours, count.

    Returns
    -------
    motion : float
        0 when no vertex is near the hair.
    """
    if len(points) == 0 or len(before) == 0:
        return 0.0
    hair_cells = np.unique(_cell_keys(np.floor(points / reach).astype(np.int64)))
    vertex_cells = np.floor(before / reach).astype(np.int64)
    near = np.zeros(len(before), dtype=bool)
    for offset in np.stack(np.meshgrid(*[np.arange(-1, 2)] * 3, indexing="ij"), axis=-1).reshape(-1, 3):
        near |= np.isin(_cell_keys(vertex_cells + offset), hair_cells)
    if not near.any():
        return 0.0
    return float(np.linalg.norm(after[near] - before[near], axis=1).max())


def _cell_keys(cells: np.ndarray) -> np.ndarray:
    """One int64 per integer cell ``(n, 3)`` (coordinates within +-2^20 cells: +-52 km at 5 cm)."""
    shifted = cells + (1 << 20)
    return (shifted[:, 0] << 42) | (shifted[:, 1] << 21) | shifted[:, 2]


def frame_coherence(previous_points: np.ndarray, points: np.ndarray, previous_vertices: np.ndarray,
                    vertices: np.ndarray) -> dict:
    """How far a frame's hair moved against how far its body moved near it.

    Parameters
    ----------
    previous_points, points : (N, 3) float64
        The hair in the previous frame and in this one.
    previous_vertices, vertices : (V, 3) float64
        The body in the previous frame and in this one.

    Returns
    -------
    coherence : dict
        ``largest_jump_m``, ``body_motion_near_hair_m``, ``jump_bound_m`` (``JUMP_MOTION_FACTOR`` times the motion
        plus ``JUMP_ALLOWANCE_M``), ``pops`` (a jump beyond the bound) and ``particles_beyond`` (how many).
    """
    jumps = np.linalg.norm(points - previous_points, axis=1)
    motion = body_motion_near_hair(previous_points, previous_vertices, vertices)
    bound = JUMP_MOTION_FACTOR * motion + JUMP_ALLOWANCE_M
    beyond = jumps > bound
    return {"largest_jump_m": float(jumps.max()) if len(jumps) else 0.0, "body_motion_near_hair_m": motion,
            "jump_bound_m": bound, "pops": bool(beyond.any()), "particles_beyond": int(beyond.sum())}


def sequence_report(results: Sequence[RetargetResult | FrameRecord], times: Sequence[float]) -> dict:
    """The sequence's report: every frame's metrics and timings, and a summary (JSON-ready).

    Parameters
    ----------
    results : sequence of RetargetResult or FrameRecord
        From :func:`retarget_sequence`, in order (only their metrics and timings are read).
    times : sequence of float
        Each frame's number (time code).
    """
    frames = [{"time": float(time), "metrics": result.metrics, "timings_s": result.timings}
              for result, time in zip(results, times)]
    coherence = [result.metrics["coherence"] for result in results[1:]]
    seconds = [result.timings["frame"] for result in results]
    return {
        "frames": frames,
        "summary": {
            "frames": len(results),
            "penetrating_particles_max": max((int(r.metrics["penetrating_particles"]) for r in results), default=0),
            "largest_jump_m": max((c["largest_jump_m"] for c in coherence), default=0.0),
            "frames_that_pop": sum(bool(c["pops"]) for c in coherence),
            "first_frame_s": seconds[0] if seconds else 0.0,
            "later_frames_median_s": float(np.median(seconds[1:])) if len(seconds) > 1 else None,
        },
    }


@dataclass(frozen=True)
class FrameRecord:
    """What a sequence's report keeps of a frame: its metrics and timings, not its arrays (a long sequence of a large
    groom would hold every frame's hair otherwise)."""

    metrics: dict
    timings: dict

    @classmethod
    def of(cls, result: RetargetResult) -> FrameRecord:
        return cls(result.metrics, result.timings)


#: the arrays of a saved :class:`SolvedFrames` (``.npz``), beside its ``meta`` (JSON bytes)
SOLVED_FRAME_ARRAYS = ("times", "points", "inside", "crossing", "body_vertices")


@dataclass
class SolvedFrames:
    """Every frame of a solved sequence, as a service keeps it: what the animated result files are written from (in
    any animated format, or one frame in any format) and what a viewer plays.

    Attributes
    ----------
    times : (F,) float64
        Each frame's time code.
    points : (F, N, 3) float32
        Each frame's hair, hairport's frame (meters); float32, as the animated formats store points.
    inside, crossing : (F, ceil(N / 8)) uint8
        Each frame's particles inside the body and those starting a segment through it, as packed bits
        (the display scene's ``inside`` and ``crossing``).
    body_vertices : (F, V, 3) float32
        Each frame's body, hairport's frame.
    groom : InputFrame
        The groom file's units and axes (the result files are written in them).
    frames_per_second : float
    """

    times: np.ndarray
    points: np.ndarray
    inside: np.ndarray
    crossing: np.ndarray
    body_vertices: np.ndarray
    groom: InputFrame
    frames_per_second: float = FRAMES_PER_SECOND

    @classmethod
    def empty(cls, times: Sequence[float], n_particles: int, n_vertices: int, groom: InputFrame,
              frames_per_second: float = FRAMES_PER_SECOND) -> SolvedFrames:
        """Room for ``len(times)`` frames, filled by :meth:`put` (allocated once: no copy of every frame at the end)."""
        count, packed = len(times), (n_particles + 7) // 8
        return cls(np.asarray(times, dtype=np.float64), np.zeros((count, n_particles, 3), np.float32),
                   np.zeros((count, packed), np.uint8), np.zeros((count, packed), np.uint8),
                   np.zeros((count, n_vertices, 3), np.float32), groom, float(frames_per_second))

    @staticmethod
    def bytes_needed(n_frames: int, n_particles: int, n_vertices: int) -> int:
        """What :meth:`empty` allocates (bytes)."""
        return n_frames * (12 * n_particles + 2 * ((n_particles + 7) // 8) + 12 * n_vertices)

    def put(self, number: int, result: RetargetResult, body: Character) -> None:
        """Keep frame ``number``'s result (its ``inside`` and ``crossing`` as the pipeline measured them) and body."""
        n_particles = result.hair.n_particles
        self.points[number] = result.hair.points
        for bits, mask in ((self.inside, result.inside), (self.crossing, result.crossing)):
            bits[number] = np.packbits(np.zeros(n_particles, bool) if mask is None else np.asarray(mask, bool))
        self.body_vertices[number] = body.vertices

    def animation(self) -> Animation:
        """Every frame's points in the groom file's axes (meters), for :func:`write_hair_frames` with
        ``units=groom.units``."""
        return Animation(self.times, [self.groom.axes_out(points).astype(np.float32) for points in self.points],
                         self.frames_per_second)

    def hair_at(self, layout: Hair, number: int) -> Hair:
        """Frame ``number``'s hair in the groom file's axes (meters), with ``layout``'s strands and attributes."""
        return layout.with_points(self.groom.axes_out(self.points[number]))

    def scene_at(self, scene: dict[str, np.ndarray], number: int) -> dict[str, np.ndarray]:
        """A display scene (:func:`~hairport.solver.documents.display_scene` of frame 0) at frame ``number``: its hair,
        flags and body replaced by that frame's."""
        return {**scene, "points": self.points[number], "inside": self.inside[number],
                "crossing": self.crossing[number], "body_vertices": self.body_vertices[number]}

    def save(self, path: str | os.PathLike) -> None:
        meta = {"groom": self.groom.to_dict(), "frames_per_second": self.frames_per_second}
        with open(path, "wb") as handle:
            np.savez(handle, **{name: getattr(self, name) for name in SOLVED_FRAME_ARRAYS},
                     meta=np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8))

    @classmethod
    def load(cls, path: str | os.PathLike) -> SolvedFrames:
        """What :meth:`save` wrote (a file of another kind is an ``InputError``, code ``bad_frames``)."""
        try:
            with np.load(path, allow_pickle=False) as stored:
                arrays = {name: stored[name] for name in SOLVED_FRAME_ARRAYS}
                meta = json.loads(stored["meta"].tobytes())
        except (OSError, KeyError, ValueError) as error:
            raise InputError(f"not a sequence's saved frames: {error}", os.fspath(path), "bad_frames") from None
        return cls(**arrays, groom=InputFrame(**meta["groom"]), frames_per_second=meta["frames_per_second"])

    def check_frame(self, number: int) -> int:
        """``number`` if it names a frame (0 to F - 1), else ``bad_frames``."""
        if not 0 <= number < len(self.times):
            raise InputError(f"frame {number} is not one of the sequence's {len(self.times)} frames (0 to "
                             f"{len(self.times) - 1})", "frame", "bad_frames")
        return number
