"""One job's fine level over several workers (worker/fine.py), with real processes: the tests' Redis, three
``hairport worker`` processes of one child each, the FastAPI app in-process.

A 400-strand groom with 20 guides on the toy characters; chunks of at most 3,000 particles, so the fine
level (15,200 particles) is six chunk tasks. The iteration tolerances are 0, so every chunk runs its
iteration cap and takes long enough to be seen (and killed) while it runs.
"""

from __future__ import annotations

import json
import os
import signal
import time

import numpy as np
import pytest

from .deployment import in_process_app, kill_workers, service_env, spawn_worker, wait_for_workers
from .test_service_api import AUTH, upload_character, wait_for

#: particles per chunk for this module's deployment, and the iteration cap that keeps each chunk busy
CHUNK_PARTICLES = 3_000
SLOW = {"method": "multiscale", "step_tolerance": 0, "energy_tolerance": 0}
PERIODS = dict(HAIRPORT_HEARTBEAT_SECONDS="1", HAIRPORT_STALE_AFTER_SECONDS="8", HAIRPORT_SWEEP_SECONDS="2",
               HAIRPORT_LOST_AFTER_SECONDS="30", HAIRPORT_FINE_CHUNK_PARTICLES=str(CHUNK_PARTICLES))
JOB_TIMEOUT = 300
DONE = ("succeeded", "failed", "cancelled")


@pytest.fixture(scope="module")
def spread(tmp_path_factory, redis_url):
    storage = tmp_path_factory.mktemp("spread-storage")
    env = service_env(storage, redis_url, **PERIODS)
    with in_process_app(env) as (settings, queue, client):
        workers = {name: spawn_worker(name, env, storage, warmup=False) for name in ("s1", "s2", "s3")}
        wait_for_workers(queue, workers, {name: storage / f"{name}.log" for name in workers})
        yield {"client": client, "storage": storage, "settings": settings, "workers": workers}
        kill_workers(workers)


@pytest.fixture(scope="module")
def inputs(spread, tmp_path_factory):
    from hairport.solver.io.hair import write_hair
    from hairport.solver.synthetic import toy
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import write_character

    folder = tmp_path_factory.mktemp("spread-inputs")
    source = toy.toy_character(name="source")
    target = toy.toy_character(head_scale=(1.1, 0.95, 1.05), neck_length=0.15, shoulder_width=0.42, name="target")
    for name, character in (("source", source), ("target", target)):
        write_character(character, folder / f"{name}.obj", folder / f"{name}.skeleton.json")
    write_hair(folder / "hair.data", generate_groom(source, "long", 400, 40, seed=3))
    client = spread["client"]
    ids = {name: upload_character(client, {"dir": folder}, name).json()["id"] for name in ("source", "target")}
    response = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": ids["source"], "guides": "20"},
                           files={"hair": ("groom.data", (folder / "hair.data").read_bytes())})
    assert response.status_code == 201, response.text
    ids["hairstyle"] = response.json()["id"]
    return ids


def record(spread, job_id: str) -> dict:
    return json.loads((spread["storage"] / "records" / "jobs" / f"{job_id}.json").read_text())


def submit(spread, inputs, options: dict) -> str:
    response = spread["client"].post("/v1/retargets", headers=AUTH, json={
        "hairstyle_id": inputs["hairstyle"], "target_character_ids": [inputs["target"]], "options": options})
    assert response.status_code == 202, response.text
    return response.json()["jobs"][0]["id"]


def single_process_points(spread, job: dict) -> np.ndarray:
    """The job's result as one process computes it: the stored artifact and target, the same options."""
    from hairport import solver
    from hairport.records import ArtifactRecord, JobRecord
    from hairport.repository import Repository
    from hairport.storage import LocalStorage
    from hairport.worker.loading import job_inputs

    repository = Repository(LocalStorage(spread["storage"]))
    job_record = JobRecord.model_validate(job)
    artifact = repository.get(ArtifactRecord, job_record.artifact_key)
    adaptable, target, target_input = job_inputs(repository, spread["settings"], job_record, artifact)
    result = solver.retarget(adaptable, target, solver.RetargetOptions(**job_record.options),
                             target_input=target_input)
    return solver.hair_in_frame(adaptable.frame, result.hair).points


def result_points(spread, job_id: str) -> np.ndarray:
    from hairport import solver

    response = spread["client"].get(f"/v1/jobs/{job_id}/result", headers=AUTH, params={"format": "npz"})
    assert response.status_code == 200
    path = spread["storage"] / f"{job_id}.npz"
    path.write_bytes(response.content)
    return solver.read_hair(path).points


def test_one_job_runs_as_chunk_tasks_on_several_workers_and_equals_one_process_bit_for_bit(spread, inputs):
    job_id = submit(spread, inputs, {**SLOW, "max_iterations": 60})
    done = wait_for(spread["client"], f"/v1/jobs/{job_id}", lambda body: body["state"] in DONE, JOB_TIMEOUT)
    assert done["state"] == "succeeded", done
    job = record(spread, job_id)
    chunks = job["fine"]["chunks"]
    assert len(chunks) == 6  # 380 normal strands of 40 particles, 75 to a chunk
    assert all(chunk["state"] == "done" and chunk["attempts"] == 1 for chunk in chunks)
    assert all(chunk["particles"] <= CHUNK_PARTICLES for chunk in chunks)
    assert [chunk["first_strand"] for chunk in chunks[1:]] == [chunk["stop_strand"] for chunk in chunks[:-1]]
    assert [(c["index"], c["worker"], c["state"]) for c in done["chunks"]] == [
        (c["index"], c["worker"], c["state"]) for c in chunks]  # the API shows the record's chunks
    workers = {chunk["worker"] for chunk in chunks}
    assert len(workers) >= 2, chunks  # the job's own worker and at least one other
    assert job["fine"]["run_token"] == job["run_token"] and job["attempts"] == 1
    assert done["metrics"]["penetrating_particles"] == 0
    assert np.array_equal(result_points(spread, job_id), single_process_points(spread, job))
    # the chunks' inputs and points went through the storage as blobs (no folder shared by the workers)
    others = [chunk for chunk in chunks if chunk["worker"] != job["worker"]]
    assert others and all(len(chunk["result"]) == 64 for chunk in others)


def test_a_worker_killed_during_a_chunk_costs_that_chunk_only(spread, inputs):
    job_id = submit(spread, inputs, {**SLOW, "max_iterations": 400})
    deadline = time.time() + JOB_TIMEOUT
    victim = None
    while victim is None:
        assert time.time() < deadline, record(spread, job_id)
        job = record(spread, job_id)
        own = job.get("worker_pid")
        for chunk in (job.get("fine") or {}).get("chunks", []):
            if chunk["state"] == "running" and chunk["worker_pid"] not in (None, own) and chunk["progress"] > 0:
                victim = chunk
                break
        time.sleep(0.05)
    os.kill(victim["worker_pid"], signal.SIGKILL)  # the pool child solving the chunk, as the OOM killer would
    done = wait_for(spread["client"], f"/v1/jobs/{job_id}", lambda body: body["state"] in DONE, JOB_TIMEOUT)
    assert done["state"] == "succeeded", done
    job = record(spread, job_id)
    attempts = {chunk["index"]: chunk["attempts"] for chunk in job["fine"]["chunks"]}
    assert attempts[victim["index"]] == 2, job["fine"]
    assert all(count == 1 for index, count in attempts.items() if index != victim["index"]), attempts
    assert job["attempts"] == 1 and done["metrics"]["penetrating_particles"] == 0
    assert all(process.poll() is None for process in spread["workers"].values())  # the worker lives on


def test_cancelling_a_spread_job_stops_its_chunks(spread, inputs):
    job_id = submit(spread, inputs, {**SLOW, "max_iterations": 1000})
    wait_for(spread["client"], f"/v1/jobs/{job_id}",
             lambda body: record(spread, job_id).get("fine") is not None, JOB_TIMEOUT)
    response = spread["client"].delete(f"/v1/jobs/{job_id}", headers=AUTH)
    assert response.status_code == 200, response.text
    done = wait_for(spread["client"], f"/v1/jobs/{job_id}", lambda body: body["state"] in DONE, JOB_TIMEOUT)
    assert done["state"] == "cancelled", done
    deadline = time.time() + 30
    while any(chunk["state"] == "running" and chunk["heartbeat_at"] and time.time() - chunk["heartbeat_at"] < 3
              for chunk in record(spread, job_id)["fine"]["chunks"]):
        assert time.time() < deadline, record(spread, job_id)["fine"]
        time.sleep(0.5)
