"""A job's fine level in chunks (worker/fine.py), called as plain functions on a real storage (no Celery): the
job's run alone, chunk bodies run as tasks would run them, obsolete and gone chunks, a failing chunk."""

import os
import subprocess
import sys
import time

import numpy as np
import pytest

from hairport import solver
from hairport.records import CHUNK_DONE, CHUNK_FAILED, CHUNK_QUEUED, CHUNK_RUNNING, RUNNING, now
from hairport.worker import fine, runner
from hairport.worker.fine import FineDispatch, claim_chunk, plan_chunks, run_fine_chunk
from hairport.worker.loading import job_inputs

from .test_runner import add_job, world  # noqa: F401 - the storage with toy characters and a preprocessed groom

#: particles per chunk here: the toy groom's 20 normal strands of 8 particles are 4 chunks
CHUNK_PARTICLES = 40


@pytest.fixture
def settings(world):  # noqa: F811
    return world["settings"].model_copy(update={"fine_chunk_particles": CHUNK_PARTICLES, "heartbeat_seconds": 0.2})


def one_process_points(world, job):  # noqa: F811
    repository = world["repository"]
    adaptable, target, target_input = job_inputs(repository, world["settings"], job, repository.artifact(job.artifact_key))
    result = solver.retarget(adaptable, target, solver.RetargetOptions(**job.options), target_input=target_input)
    return solver.hair_in_frame(adaptable.frame, result.hair).points


def result_points(world, job_id, tmp_path):  # noqa: F811
    job = world["repository"].job(job_id)
    blob = world["repository"].storage.blob(job.outputs["npz"].sha256, ".npz")
    return solver.read_hair(blob.path).points


class Recorder:
    """A dispatch that only records what was sent and revoked (no worker takes the chunks)."""

    def __init__(self):
        self.sent, self.revoked = [], []

    def dispatch(self) -> FineDispatch:
        return FineDispatch(send=lambda *message: self.sent.append(message), revoke=self.revoked.append)


def test_chunks_are_whole_strands_of_about_the_chunk_size_and_at_most_the_cap():
    counts = np.array([8] * 20)
    assert plan_chunks(counts, 40, 32) == [(0, 5), (5, 10), (10, 15), (15, 20)]
    assert plan_chunks(counts, 40, 2) == [(0, 10), (10, 20)]  # 160 particles in at most 2 chunks
    assert plan_chunks(counts, 1000, 32) == [(0, 20)]
    assert plan_chunks(np.array([3, 50, 2]), 10, 32) == [(0, 1), (1, 2), (2, 3)]


def test_the_jobs_own_run_solves_every_chunk_nobody_takes_bit_for_bit(world, settings, tmp_path):  # noqa: F811
    recorder = Recorder()
    job = add_job(world)
    runner.run_retarget(world["repository"], settings, job.id, "coordinator@host", chunks=recorder.dispatch())
    done = world["repository"].job(job.id)
    assert done.state == "succeeded", done.error
    chunks = done.fine.chunks
    assert [(c.first_strand, c.stop_strand) for c in chunks] == [(0, 5), (5, 10), (10, 15), (15, 20)]
    assert all(c.state == CHUNK_DONE and c.attempts == 1 and c.worker == "coordinator@host" for c in chunks)
    assert sorted(message[2] for message in recorder.sent) == [0, 1, 2, 3]
    assert [message[3] for message in sorted(recorder.sent, key=lambda m: m[2])] == [c.task_id for c in chunks]
    assert done.fine.run_token == done.run_token and recorder.revoked == []
    assert np.array_equal(result_points(world, job.id, tmp_path), one_process_points(world, job))
    # the run's own chunks stay in its memory; their inputs are a blob no record keeps (the orphan sweep's)
    assert all(c.result is None for c in chunks)
    assert_swept_but_outputs(world["repository"].storage, done, [done.fine.inputs])
    # the messages arriving now are no-ops: the job is over
    for job_id, token, index, task_id in recorder.sent:
        run_fine_chunk(world["repository"], settings, job_id, token, index, "late@host", task_id)
    assert world["repository"].job(job.id).fine.chunks == chunks


def test_chunks_solved_by_their_tasks_give_the_same_result(world, settings, tmp_path):  # noqa: F811
    """Each message is handled at once, as a task on another worker would (from the artifact, the target and
    the saved inputs): the job's run finds every chunk done and solves none."""
    repository = world["repository"]

    def send(job_id, token, index, task_id):
        run_fine_chunk(repository, settings, job_id, token, index, f"other{index}@host", task_id)

    job = add_job(world)
    runner.run_retarget(repository, settings, job.id, "coordinator@host", chunks=FineDispatch(send, lambda _: None))
    done = repository.job(job.id)
    assert done.state == "succeeded", done.error
    assert [c.worker for c in done.fine.chunks] == [f"other{i}@host" for i in range(4)]
    assert all(c.state == CHUNK_DONE and c.seconds > 0 for c in done.fine.chunks)
    assert done.metrics["penetrating_particles"] == 0
    assert np.array_equal(result_points(world, job.id, tmp_path), one_process_points(world, job))
    # each task's points came back as a blob (another host would fetch it from the object store by its digest)
    assert len({c.result for c in done.fine.chunks}) == 4
    assert_swept_but_outputs(repository.storage, done, [done.fine.inputs, *(c.result for c in done.fine.chunks)])


def assert_swept_but_outputs(storage, job, scratch: list[str]) -> None:
    """The fine level's blobs are there until an orphan sweep after the job, which keeps the job's outputs."""
    assert all(storage.blob(digest, fine.FINE_SUFFIX) is not None for digest in scratch)
    storage.sweep_orphans(0.0, now=time.time() + 1.0)
    assert all(storage.blob(digest, fine.FINE_SUFFIX) is None for digest in scratch)
    assert all(storage.blob(ref.sha256, ref.suffix) is not None for ref in job.outputs.values())


def test_a_small_fine_level_or_no_queue_stays_in_the_jobs_own_run(world, settings):  # noqa: F811
    repository = world["repository"]
    job = add_job(world)
    big = settings.model_copy(update={"fine_chunk_particles": 1000})
    recorder = Recorder()
    runner.run_retarget(repository, big, job.id, "w@host", chunks=recorder.dispatch())
    assert repository.job(job.id).state == "succeeded" and repository.job(job.id).fine is None
    assert recorder.sent == []
    job = add_job(world)
    runner.run_retarget(repository, settings, job.id, "w@host", chunks=None)
    assert repository.job(job.id).state == "succeeded" and repository.job(job.id).fine is None


def test_a_chunk_that_fails_on_its_input_fails_the_job_once_with_its_reason(world, settings):  # noqa: F811
    repository = world["repository"]
    revoked = []

    def send(job_id, token, index, task_id):
        if index == 3:  # the first sent (they go out last first): its inputs are damaged before it runs
            inputs = repository.storage.blob(repository.job(job_id).fine.inputs, fine.FINE_SUFFIX).path
            inputs.write_bytes(b"PK\x03\x04 not an archive")
            run_fine_chunk(repository, settings, job_id, token, index, "other@host", task_id)

    job = add_job(world)
    runner.run_retarget(repository, settings, job.id, "coordinator@host", chunks=FineDispatch(send, revoked.append))
    done = repository.job(job.id)
    assert done.state == "failed", done
    assert done.error.code == "internal" and "chunk 3 of the fine level (strands 15..19)" in done.error.message
    assert done.fine.chunks[3].state == CHUNK_FAILED and done.fine.chunks[3].attempts == 1
    assert sorted(revoked) == sorted(c.task_id for c in done.fine.chunks if c.state == CHUNK_QUEUED)


def _running_job_with_chunks(world, settings, **chunk_fields):  # noqa: F811
    """A job record as its run leaves it once the chunks are listed (chunk 0 with ``chunk_fields``)."""
    repository = world["repository"]
    job = add_job(world)
    chunks = [fine.FineChunk(index=i, first_strand=5 * i, stop_strand=5 * i + 5, particles=40, task_id=f"t{i}")
              for i in range(4)]
    chunks[0] = chunks[0].model_copy(update=chunk_fields)
    repository.set_job(job.id, state=RUNNING, run_token="run1", heartbeat_at=now(),
                       fine=fine.FineRun(run_token="run1", inputs="0" * 64, chunks=chunks).model_dump())
    return job


def test_a_message_claims_only_its_own_queued_chunk_of_the_current_run(world, settings):  # noqa: F811
    repository = world["repository"]
    job = _running_job_with_chunks(world, settings)
    assert claim_chunk(repository, settings, job.id, "run0", 0, "w@h", "t0") is None  # another run's
    assert claim_chunk(repository, settings, job.id, "run1", 0, "w@h", "t1") is None  # another chunk's message
    assert claim_chunk(repository, settings, job.id, "run1", 9, "w@h", "t0") is None  # no such chunk
    claim = claim_chunk(repository, settings, job.id, "run1", 0, "w@h", "t0")
    assert claim is not None
    chunk = repository.job(job.id).fine.chunks[0]
    assert chunk.state == CHUNK_RUNNING and chunk.attempts == 1 and chunk.worker_pid == os.getpid()
    assert claim_chunk(repository, settings, job.id, "run1", 0, "w@h", "t0") is None  # held by a live run
    repository.set_job(job.id, cancel_requested=True)
    assert claim_chunk(repository, settings, job.id, "run1", 1, "w@h", "t1") is None  # the job is being cancelled


def test_a_chunk_whose_process_died_or_went_silent_is_claimed_again(world, settings):  # noqa: F811
    repository = world["repository"]
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    job = _running_job_with_chunks(world, settings, state=CHUNK_RUNNING, attempts=1, claim="old",
                                   worker_host=fine.HOST, worker_pid=dead.pid, heartbeat_at=now())
    claim = claim_chunk(repository, settings, job.id, "run1", 0, "w@h", "t0")
    assert claim is not None and repository.job(job.id).fine.chunks[0].attempts == 2
    assert not fine.ChunkClaim(repository, job.id, "run1", 0, "old").write(state=CHUNK_DONE)  # the dead run's write
    job = _running_job_with_chunks(world, settings, state=CHUNK_RUNNING, attempts=1, claim="old",
                                   worker_host="elsewhere", worker_pid=1,
                                   heartbeat_at=now() - settings.stale_after_seconds - 1)
    assert claim_chunk(repository, settings, job.id, "run1", 0, "w@h", "t0") is not None


def test_a_transient_error_hands_the_chunk_back_uncounted(world, settings):  # noqa: F811
    repository = world["repository"]
    job = _running_job_with_chunks(world, settings)
    claim = claim_chunk(repository, settings, job.id, "run1", 1, "w@h", "t1")
    assert repository.job(job.id).fine.chunks[1].attempts == 1
    assert claim.release()
    chunk = repository.job(job.id).fine.chunks[1]
    assert (chunk.state, chunk.claim, chunk.attempts) == (CHUNK_QUEUED, None, 0)
    assert not claim.release()  # no longer this claim's
    again = claim_chunk(repository, settings, job.id, "run1", 1, "w@h", "t1")
    assert again is not None and repository.job(job.id).fine.chunks[1].attempts == 1
