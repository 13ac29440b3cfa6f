"""A sequence job's run, called as a plain function on a real storage with toy characters (no Celery): its frames
read from characters in order, the frame counts written as it goes, every frame kept, and the refusals."""

import numpy as np
import pytest

from hairport import solver
from hairport.records import BlobRef, SequencePlan
from hairport.solver import sequence as solver_sequence
from hairport.solver.io.character.obj import write_obj
from hairport.worker import runner, sequences
from hairport.worker.loading import adaptable_at, blob_path

from .test_runner import add_job, world  # noqa: F401 - the module's storage and toy characters


def sequence_job(world, names, output_format="usda", **plan):  # noqa: F811
    ids = world["ids"]
    return add_job(world, target=names[0], output_format=output_format, sequence=SequencePlan(
        frames_from="characters", character_ids=[ids[name].id for name in names], **plan))


def test_characters_in_order_are_solved_frame_by_frame_and_kept(world):  # noqa: F811
    repository, settings = world["repository"], world["settings"]
    job = sequence_job(world, ["source", "target", "source"])
    written = []
    artifact = repository.artifact(job.artifact_key)
    adaptable = adaptable_at(str(blob_path(repository, BlobRef(sha256=artifact.sha256, suffix=artifact.suffix))))
    progress = runner.JobProgress(repository, job.id)
    outputs, metrics, timings = sequences.solve_and_store(repository, settings, job, adaptable, progress,
                                                          lambda **fields: written.append(fields))
    assert written == [{"frames": 3, "frames_done": 0}, {"frames_done": 1}, {"frames_done": 2}, {"frames_done": 3}]
    assert set(outputs) == {"npz", "usda", "report", "preview", "scene", "frames"}
    assert metrics["frames"] == 3 and metrics["penetrating_particles_max"] == 0
    assert [frame["time"] for frame in metrics["frames_detail"]] == [0.0, 1.0, 2.0]
    # each stage's seconds summed over the frames: the three frames' solves, the two bodies' surfaces built once each
    assert timings["frame"] >= timings["solve"] > 0 and timings["target_cache_build"] > 0
    kept = solver_sequence.SolvedFrames.load(repository.storage.blob(outputs["frames"].sha256, ".npz").path)
    assert kept.points.shape == (3, adaptable.hair.n_particles, 3) and kept.points.dtype == np.float32
    # the body goes to the target and back, and so does the hair: frames 0 and 2 are one body
    assert np.abs(kept.body_vertices[0] - kept.body_vertices[2]).max() == 0.0
    assert np.abs(kept.body_vertices[1] - kept.body_vertices[0]).max() > 0.01
    assert np.abs(kept.points[2] - kept.points[0]).max() < np.abs(kept.points[1] - kept.points[0]).max()
    assert np.unpackbits(kept.inside).sum() == 0


def test_a_sequence_job_runs_through_the_job_body(world):  # noqa: F811
    repository = world["repository"]
    job = sequence_job(world, ["source", "target"], frames="0:1", temporal=1e4)
    runner.run_retarget(repository, world["settings"], job.id, "w1@host")
    done = repository.job(job.id)
    assert done.state == "succeeded" and done.frames == 2 and done.frames_done == 2, done.error
    assert done.metrics["frames_that_pop"] == 0 and done.timings["job"] > 0 and "usda" in done.outputs


@pytest.mark.parametrize("change, code", [("units", "units_mismatch"), ("topology", "sequence_topology")])
def test_frames_that_are_not_one_body_fail_the_job(world, change, code):  # noqa: F811
    """A character of unknown units among ones read in meters; a body of another mesh."""
    repository, ids = world["repository"], world["ids"]
    if change == "units":
        target = ids["target"]
        loaded = solver.read_character(blob_path(repository, target.mesh), skeleton_path=blob_path(
            repository, target.skeleton))[0]
        write_obj(world["root"] / "bare.obj", loaded.vertices, loaded.faces, "no units stated")
        bare = target.model_copy(update={"id": "c" * 32, "skeleton": None, "mesh": BlobRef(
            sha256=repository.storage.save_file(world["root"] / "bare.obj", ".obj").sha256, suffix=".obj")})
        repository.put(bare, bare.id)
        job = add_job({**world, "ids": {**ids, "bare": bare}}, target="source", output_format="usda",
                      sequence=SequencePlan(frames_from="characters", character_ids=[ids["source"].id, bare.id]))
    else:
        job = sequence_job(world, ["source", "other"])
    runner.run_retarget(repository, world["settings"], job.id, "w1@host")
    failed = repository.job(job.id)
    assert failed.state == "failed" and failed.error.code == code and failed.outputs is None, failed.error


def test_the_metrics_keep_the_summary_and_each_frames_coherence():
    report = solver_sequence.sequence_report(
        [solver_sequence.FrameRecord({"penetrating_particles": 0}, {"frame": 1.0}),
         solver_sequence.FrameRecord({"penetrating_particles": 0, "coherence": {
             "largest_jump_m": 0.002, "jump_bound_m": 0.003, "pops": False, "particles_beyond": 0,
             "body_motion_near_hair_m": 0.001}}, {"frame": 0.25})], [10.0, 11.0])
    metrics = sequences.sequence_metrics(report)
    assert metrics["frames"] == 2 and metrics["later_frames_median_s"] == 0.25
    assert metrics["frames_detail"] == [
        {"time": 10.0, "penetrating_particles": 0},
        {"time": 11.0, "penetrating_particles": 0, "largest_jump_m": 0.002, "jump_bound_m": 0.003, "pops": False}]


def test_a_failed_wrap_of_a_frame_names_the_axes_the_frames_were_read_in():
    """A refusal from a frame's solve is explained as a single job's is (the axes that were fitted), once."""
    found = {"axes_how": "fitted", "up": "+Z", "front": "-Y"}

    def frames():
        yield "frame 0"
        raise solver.InputError("the source body could not be wrapped onto the target", "ball.obj", "wrap_failed")

    got = []
    with pytest.raises(solver.InputError) as error:
        for number, frame in sequences._explained(frames(), "auto", found):
            got.append((number, frame))
    assert got == [(0, "frame 0")] and error.value.code == "wrap_failed" and error.value.source == "ball.obj"
    assert error.value.problem.startswith("the target was read with up +Z and front -Y (fitted; give the character's")
    assert error.value.problem.count("fitted") == 1 and error.value.problem.endswith("could not be wrapped onto the target")
