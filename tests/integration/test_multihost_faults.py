"""Faults of a multi-host deployment, with real servers and a real worker: PostgreSQL restarted in the middle of a
job, the S3-compatible store stopped and started again in the middle of a job. Every job ends (succeeded, or
failed with a code), no record is lost, and the index still matches the records.

The servers are this module's own (a test stops them); the API is in-process, the worker a ``hairport worker``
process with a cache folder of its own."""

from __future__ import annotations

import time

import pytest

from tests.servers.postgres import PostgresServer
from tests.servers.seaweed import SeaweedServer

from .test_multihost import inputs, url_deployment  # noqa: F401
from .test_service_api import AUTH, wait_for

PERIODS = dict(HAIRPORT_HEARTBEAT_SECONDS="1", HAIRPORT_STALE_AFTER_SECONDS="8", HAIRPORT_SWEEP_SECONDS="2",
               HAIRPORT_LOST_AFTER_SECONDS="30", HAIRPORT_FINE_CHUNK_PARTICLES="1000000")
#: a job long enough to be caught running (the iteration tolerances 0: every strand runs the cap)
SLOW = {"method": "multiscale", "step_tolerance": 0, "energy_tolerance": 0, "max_iterations": 400}
JOB_TIMEOUT = 420
DONE = ("succeeded", "failed", "cancelled")
#: seconds the database stays down (the job's progress writes meet it)
OUTAGE_SECONDS = 4.0
#: seconds the store stays down: longer than the rest of the slow job's solve (~15 s here), so that the job meets
#: it when it writes its outputs
STORE_OUTAGE_SECONDS = 20.0


@pytest.fixture(scope="module")
def servers():
    with PostgresServer() as postgres, SeaweedServer() as seaweed:
        yield {"postgres": postgres, "seaweed": seaweed}


@pytest.fixture(scope="module")
def hosts(tmp_path_factory, redis_url, servers):
    with url_deployment(tmp_path_factory, redis_url, servers["postgres"].url, servers["seaweed"], "faults",
                        ("host1",), PERIODS) as deployment:
        yield deployment


def running_job(hosts, inputs) -> str:  # noqa: F811
    """A slow job, once its worker has started solving it."""
    client = hosts["client"]
    response = client.post("/v1/retargets", headers=AUTH, json={
        "hairstyle_id": inputs["long"], "target_character_ids": [inputs["target"]], "options": SLOW})
    assert response.status_code == 202, response.text
    job_id = response.json()["jobs"][0]["id"]
    wait_for(client, f"/v1/jobs/{job_id}", lambda body: body["state"] == "running" and body["progress"] > 0.1,
             JOB_TIMEOUT)
    return job_id


def assert_ended_whole(hosts, job_id: str) -> dict:
    """The job ended; succeeded, its result is there; failed, with a code and no outputs; the index matches."""
    from hairport.repository import Repository
    from hairport.storage import open_storage

    client = hosts["client"]
    done = wait_for(client, f"/v1/jobs/{job_id}", lambda body: body["state"] in DONE, JOB_TIMEOUT)
    repository = Repository(open_storage(hosts["settings"]))
    job = repository.job(job_id)
    if done["state"] == "succeeded":
        assert client.get(f"/v1/jobs/{job_id}/result", headers=AUTH).status_code == 200
        assert done["metrics"]["penetrating_particles"] == 0
    else:
        assert job.error is not None and job.error.code != "internal" and job.outputs is None, job.error
    counts = repository.job_counts()
    records = [job for job in repository.storage.list_records("jobs")]
    assert sum(counts.values()) == len(records)
    return done


def test_a_database_restart_in_the_middle_of_a_job_loses_no_job_and_no_result(hosts, inputs, servers):  # noqa: F811
    job_id = running_job(hosts, inputs)
    servers["postgres"].stop()
    time.sleep(OUTAGE_SECONDS)
    servers["postgres"].start_again()
    back = time.time()
    done = assert_ended_whole(hosts, job_id)
    assert done["state"] == "succeeded", done
    assert done["finished_at"] > back, "the job ended before the outage: it tested nothing"
    assert hosts["workers"]["host1"].poll() is None  # the worker lives on


def test_the_store_stopped_in_the_middle_of_a_job_ends_it_whole(hosts, inputs, servers):  # noqa: F811
    job_id = running_job(hosts, inputs)
    stopped = time.time()
    servers["seaweed"].stop()
    # down for longer than the rest of the solve: the job meets the outage when it writes its outputs, hands its
    # run back and is retried, and the retry finds the store back
    time.sleep(STORE_OUTAGE_SECONDS)
    servers["seaweed"].start()
    done = assert_ended_whole(hosts, job_id)
    # the run that met the outage handed the job back (a transient error counts no attempt); a new run, started
    # after the store went down, wrote the outputs
    assert done["state"] == "succeeded" and done["started_at"] > stopped and done["attempts"] == 1, done
    assert hosts["workers"]["host1"].poll() is None
