"""A sequence job's run: read its frames, solve them in order (each warm from the one before), keep every frame.

The frames are one animated character's (read from its stored file at the job's frame range: a USD stage's
time-sampled points, a glTF's morph targets, an Alembic mesh) or several characters' in order. Each frame's
collision surface comes from the per-target cache, as a single job's does; a sequence's fine levels are solved in
its own run (the chunks of other workers read one target body). The outputs, written only when every frame is
solved: the animated result file, frame 0's result as the lossless copy (the layout every download is written
from), every frame kept (:class:`~hairport.solver.sequence.SolvedFrames`: downloads of any frame or animated
format, the dashboard's playback), frame 0's preview and scene, and the sequence's report.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hairport import solver
from hairport.outputs import OutputSet, add_result, hair_as_written
from hairport.records import FRAMES_OUTPUT, FROM_CHARACTERS, LOSSLESS_OUTPUT, BlobRef, CharacterRecord, JobRecord
from hairport.repository import Repository
from hairport.settings import Settings
from hairport.solver import display, distributed, documents
from hairport.solver import sequence as solver_sequence

from . import bodies as body_cache
from .loading import blob_path, explained, job_options, limits, load_character, stored


@dataclass
class Frames:
    """A sequence job's bodies in hairport's frame, their time codes and rate, and what reading frame 0 found."""

    bodies: list[solver.Character]
    times: list[float]
    frames_per_second: float
    found: dict


def read_frames(repository: Repository, settings: Settings, job: JobRecord,
                adaptable: solver.AdaptableHairstyle) -> Frames:
    """The job's frames (an ``InputError`` for frames its target does not have, or characters that disagree)."""
    plan = job.sequence
    frames = None if plan.frames is None else solver_sequence.FrameRange.parse(plan.frames)
    if plan.frames_from == FROM_CHARACTERS:
        loaded, total = [], 0
        for character_id in plan.character_ids:  # every frame's mesh is held at once: bounded as it is read
            loaded.append(load_character(repository, settings, character_id))
            total += loaded[-1][0].n_vertices
            solver_sequence.check_total_vertices(total)
        units, records = {found for _, found, _ in loaded}, [record for _, _, record in loaded]
        if None in units and len(units) > 1:  # some read in meters, the others in their files' unknown units
            raise solver.InputError(f"some of the sequence's characters state their units "
                                    f"({', '.join(sorted(map(str, units - {None})))}) and others do not: give each "
                                    "its units", "sequence", "units_mismatch")
        axes = {(record.up_axis, record.front_axis) for record in records}
        if len(axes) > 1:
            raise solver.InputError("the sequence's characters were given different up or front axes: one body's "
                                    "frames share them", "sequence", "bad_axis")
        bodies, unit, record = [character for character, _, _ in loaded], loaded[0][1], records[0]
        times = list(frames.times()) if frames is not None else [float(i) for i in range(len(bodies))]
        rate = solver_sequence.FRAMES_PER_SECOND
    else:
        record = repository.get(CharacterRecord, job.target_character_id)
        if record is None:
            raise solver.InputError(f"character {job.target_character_id} does not exist", code="not_found")
        weights = None if plan.morph_weights is None else np.asarray(plan.morph_weights, dtype=np.float64)
        read = solver_sequence.read_character_frames(
            [blob_path(repository, record.mesh)], frames, units=None if record.units == solver.AUTO else record.units,
            morph_weights=weights, **limits(settings))
        bodies, unit, times, rate = read.characters, read.units, read.times, read.frames_per_second
    bodies, found = solver_sequence.canonical_sequence(adaptable.source, bodies, units=unit, up=record.up_axis,
                                                       front=record.front_axis)
    return Frames(bodies, [float(time) for time in times], float(rate), found)


def solve_and_store(repository: Repository, settings: Settings, job: JobRecord, adaptable: solver.AdaptableHairstyle,
                    progress, record_frames) -> tuple[dict[str, BlobRef], dict, dict]:
    """Solve the job's frames and store its outputs (module notes): the outputs, the job's metrics and its timings
    (each stage's seconds summed over the frames). ``record_frames(**fields)`` writes the frame counts to the job."""
    progress("loading", 0.0, "reading the target's frames")
    read = read_frames(repository, settings, job, adaptable)
    record_frames(frames=len(read.bodies), frames_done=0)
    plan, frame = job.sequence, adaptable.frame
    options = job_options(settings, job, frame)
    kept = solver_sequence.SolvedFrames.empty(read.times, adaptable.hair.n_particles, read.bodies[0].n_vertices,
                                              frame, read.frames_per_second)
    cache_seconds: dict[str, float] = {}

    def cached_surface(number: int, body: solver.Character) -> dict:
        surface, seconds = body_cache.collision_surface(repository, settings, body)
        for name, value in seconds.items():
            cache_seconds[name] = cache_seconds.get(name, 0.0) + value
        return {"collision_surface": surface}

    storage, records = repository.storage, []
    with storage.work_dir() as work, OutputSet() as written:
        files = {LOSSLESS_OUTPUT: work / "result.npz", job.output_format: work / f"result.{job.output_format}",
                 "report": work / "report.json", "preview": work / "preview.png", "scene": work / "scene.npz",
                 FRAMES_OUTPUT: work / "frames.npz"}
        solved = solver_sequence.retarget_sequence(
            adaptable, read.bodies, options, solver_sequence.SequenceOptions(plan.warm_start, plan.temporal),
            progress=progress, should_stop=progress.should_stop, frame_arguments=cached_surface,
            target_input=read.found, fine_runner=distributed.solve_here)
        for number, result in _explained(solved, options.wrap, read.found):
            kept.put(number, result, read.bodies[number])
            if number == 0:
                add_result(written, adaptable, result, read.bodies[0], {LOSSLESS_OUTPUT: files[LOSSLESS_OUTPUT]},
                           preview=files["preview"], flag_guides=job.flag_guides)
                layout = hair_as_written(adaptable, result, job.flag_guides)
                written.add(files["scene"], lambda path, result=result: display.save_scene(
                    path, documents.display_scene(adaptable, result, read.bodies[0])))
            records.append(solver_sequence.FrameRecord.of(result))
            record_frames(frames_done=number + 1)
        progress("storing", 0.99, "writing outputs")
        report = {**solver_sequence.sequence_report(records, read.times),
                  "job": {"id": job.id, "hairstyle_id": job.hairstyle_id, "target_character_id": job.target_character_id,
                          "sequence": plan.model_dump()}}
        written.add(files[job.output_format], lambda path: solver_sequence.write_hair_frames(
            path, layout, kept.animation(), units=frame.units, format=job.output_format, up_axis=frame.up))
        written.add(files[FRAMES_OUTPUT], kept.save)
        written.add_json(files["report"], report)
        written.commit()
        outputs = {name: stored(storage.save_file(path, path.suffix), path.suffix) for name, path in files.items()}
    return outputs, sequence_metrics(report), _summed_timings(records, cache_seconds)


def _explained(solved, mode: str, found: dict):
    """The numbered frames of ``solved``, a refusal of the target explained in the API's terms (:func:`.loading.explained`:
    a wrap that failed names the axes frame 0 was read in)."""
    try:
        yield from enumerate(solved)
    except solver.InputError as error:
        raise explained(error, mode, found) from None


def sequence_metrics(report: dict) -> dict:
    """What a sequence job shows of its report: the summary, and per frame its time code, penetrating particles and
    coherence (the report holds every frame's whole metrics and timings)."""
    frames = []
    for frame in report["frames"]:
        coherence = frame["metrics"].get("coherence", {})
        frames.append({"time": frame["time"], "penetrating_particles": int(frame["metrics"]["penetrating_particles"]),
                       **{name: coherence[name] for name in ("largest_jump_m", "jump_bound_m", "pops")
                          if name in coherence}})
    return {**report["summary"], "frames_detail": frames}


def _summed_timings(records: list, cache_seconds: dict[str, float]) -> dict[str, float]:
    totals = dict(cache_seconds)
    for record in records:
        for name, value in record.timings.items():
            if isinstance(value, (int, float)):
                totals[name] = totals.get(name, 0.0) + float(value)
    return totals
