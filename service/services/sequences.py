"""Sequence jobs: a retarget onto the frames of one animated character, or onto several characters in order.

What can be checked before a job exists is checked here (422 for a frame range, morph weights or options the
worker would refuse; 413 for results that could not be kept in a worker's memory budget): the frames of an
animated file are read by the job's run, and a range reaching past them fails the job with ``bad_frames``.
"""

from __future__ import annotations

from contextlib import contextmanager

from hairport import solver
from hairport.records import FROM_ANIMATION, FROM_CHARACTERS, CharacterRecord, HairstyleRecord, SequencePlan
from hairport.settings import Settings
from hairport.solver import sequence as solver_sequence

from ..errors import Problem
from ..schemas import DEFAULT_OUTPUT_FORMAT, DEFAULT_SEQUENCE_FORMAT, RetargetOptionsIn, SequenceIn
from ..uploads import input_problem

#: the share of a worker's memory budget a sequence's kept frames may take (the solve needs the rest)
FRAMES_MEMORY_SHARE = 0.5


def output_format(requested: str | None, sequence: SequenceIn | None) -> str:
    """The result's hair format: the one asked for (a sequence's must hold animation: 422 ``bad_option``), else the
    default of a single result or of a sequence."""
    if sequence is None:
        return requested or DEFAULT_OUTPUT_FORMAT
    if requested is None:
        return DEFAULT_SEQUENCE_FORMAT
    if requested not in solver_sequence.ANIMATED_FORMATS:
        raise Problem(422, "bad_option", f"output_format: a sequence's result is one animated file "
                                         f"({', '.join(solver_sequence.ANIMATED_FORMATS)}), not {requested}; each "
                                         "frame is downloadable in any format (GET /v1/jobs/{id}/result?frame=K)")
    return requested


def sequence_plans(sequence: SequenceIn, targets: list[CharacterRecord], hairstyle: HairstyleRecord,
                   options: RetargetOptionsIn, settings: Settings, landmarks: dict | None
                   ) -> list[tuple[CharacterRecord, SequencePlan]]:
    """The jobs of a request with a sequence: one per animated target, or one for all the targets in order (its
    target the first); each checked (module notes)."""
    if landmarks is not None:
        raise Problem(422, "bad_landmarks", "landmarks: they name points of one body, and a sequence's frames move "
                                            "them; send the sequence without landmarks")
    with _refused():
        solver_sequence.check_sequence_options(
            solver_sequence.SequenceOptions(warm=sequence.warm_start, temporal=sequence.temporal), options.method)
        frames = None if sequence.frames is None else solver_sequence.FrameRange.parse(sequence.frames)
    if sequence.frames_from != FROM_CHARACTERS:
        return [(target, _animation_plan(sequence, frames, target, hairstyle, settings)) for target in targets]
    if sequence.morph_weights is not None:
        raise Problem(422, "bad_frames", f"sequence.morph_weights: the frames of frames_from {FROM_CHARACTERS} "
                                         "are characters, not one glTF's morph targets")
    with _refused():
        picked = [targets[index] for index in (range(len(targets)) if frames is None else frames.pick(len(targets)))]
    _check_memory(len(picked), hairstyle, picked[0], settings)
    with _refused():
        solver_sequence.check_total_vertices(sum(target.vertices for target in picked))
    return [(picked[0], SequencePlan(**sequence.model_dump(), character_ids=[target.id for target in picked]))]


def _animation_plan(sequence: SequenceIn, frames: solver_sequence.FrameRange | None, target: CharacterRecord,
                    hairstyle: HairstyleRecord, settings: Settings) -> SequencePlan:
    weights = sequence.morph_weights
    if weights is not None and len({len(row) for row in weights}) > 1:
        raise Problem(422, "bad_frames", "sequence.morph_weights: every frame's list has one number per morph "
                                         f"target; these have {sorted({len(row) for row in weights})}")
    if frames is None and weights is None:
        raise Problem(422, "bad_frames", f"sequence.frames: the frames of an animated character (frames_from "
                                         f"{FROM_ANIMATION}) are a range of its time codes, e.g. 0:48; give one (or "
                                         "morph_weights)")
    with _refused():
        count = len(weights) if frames is None else (
            frames.count() if weights is None else len(frames.pick(len(weights))))
    _check_memory(count, hairstyle, target, settings)
    return SequencePlan(**sequence.model_dump())


@contextmanager
def _refused():
    """The solver's refusal of the sequence as the API's problem (named after the request's ``sequence``)."""
    try:
        yield
    except solver.InputError as error:
        raise input_problem(error, "sequence") from None


def _check_memory(count: int, hairstyle: HairstyleRecord, target: CharacterRecord, settings: Settings) -> None:
    """413 ``over_memory_budget`` for frames whose kept results would take more than :data:`FRAMES_MEMORY_SHARE` of
    the memory budget."""
    allowed = int(settings.memory_budget_bytes * FRAMES_MEMORY_SHARE)
    one = solver_sequence.SolvedFrames.bytes_needed(1, hairstyle.particles, target.vertices)
    if count * one > allowed:
        raise Problem(413, "over_memory_budget", f"sequence: {count:,} frames of a {hairstyle.particles:,}-particle "
                                                 f"groom on a {target.vertices:,}-vertex body keep "
                                                 f"{count * one / 2**20:,.0f} MiB of results, more than a job may "
                                                 f"(HAIRPORT_MEMORY_BUDGET_BYTES): at most {allowed // one:,} frames")
