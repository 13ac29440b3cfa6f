"""Faults with real processes: a Redis server of this module's own (stopped and started by the tests,
nothing kept on disk), real ``hairport worker`` processes, the FastAPI app in-process.

The tests run in order on one deployment and share its workers: a worker of another deployment,
a lost message, Redis down at submit, a worker host killed mid-job, a job that kills its worker
every time, cancels while Redis is down (through a real ``hairport serve``). Periods are short here
(settings below); production defaults are in hairport/settings.py.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import time
from pathlib import Path

import pytest

from ..conftest import free_port
from .deployment import in_process_app, service_env, spawn_server, spawn_worker, stop
from .test_service_api import AUTH, KEY, OTHER_KEY, assert_problem, files, upload_character, wait_for  # noqa: F401

#: short periods for the test (s): heartbeat, stale threshold, sweep period, lost-message deadline
PERIODS = dict(HAIRPORT_HEARTBEAT_SECONDS="1", HAIRPORT_STALE_AFTER_SECONDS="8", HAIRPORT_SWEEP_SECONDS="2",
               HAIRPORT_LOST_AFTER_SECONDS="3", HAIRPORT_MAX_ATTEMPTS="3", HAIRPORT_ENQUEUE_TIMEOUT_SECONDS="2")
#: what the issue promises: a job whose worker host died is stale within a minute
STALE_WITHIN_SECONDS = 60
JOB_TIMEOUT = 180
#: the file a Redis saves to in its folder (its default ``dbfilename``) and loads at start
SAVED = "dump.rdb"
DONE = ("succeeded", "failed", "cancelled")


class RedisServer:
    """A redis-server on a fixed free port that a test can stop and start again (empty: nothing persisted)."""

    def __init__(self, folder: Path):
        self.folder, self.port, self.process = folder, free_port(), None
        self.url = f"redis://127.0.0.1:{self.port}/0"

    def start(self) -> None:
        import redis

        self.process = subprocess.Popen(
            [shutil.which("redis-server"), "--port", str(self.port), "--bind", "127.0.0.1", "--save", "",
             "--appendonly", "no", "--dir", str(self.folder), "--logfile", str(self.folder / "redis.log")],
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        client = redis.Redis.from_url(self.url)
        deadline = time.monotonic() + 20
        while True:
            try:
                client.ping()
                break
            except redis.ConnectionError:  # refused, or still loading what a kept stop saved
                assert self.process.poll() is None and time.monotonic() < deadline, "redis-server did not start"
                time.sleep(0.05)
        (self.folder / SAVED).unlink(missing_ok=True)  # loaded once: the next plain restart is empty again

    def stop(self, keep: bool = False) -> None:
        """Stop the server: it forgets what it holds, or with ``keep`` saves it for the next start (as a Redis
        with persistence does)."""
        if keep:
            import redis

            redis.Redis.from_url(self.url).shutdown(save=True)
        else:
            self.process.terminate()
        self.process.wait(10)


def _env(storage: Path, redis_url: str) -> dict:
    return service_env(storage, redis_url, **PERIODS)


@pytest.fixture(scope="module")
def faults(tmp_path_factory):
    if shutil.which("redis-server") is None:
        pytest.fail("the service tests need redis-server on PATH (.ci/run installs it with apt-get)")
    server = RedisServer(tmp_path_factory.mktemp("faults-redis"))
    server.start()
    storage = tmp_path_factory.mktemp("faults-storage")
    env = _env(storage, server.url)
    with in_process_app(env) as (settings, queue, client):
        workers: dict[str, subprocess.Popen] = {}

        def start_worker(name: str, folder: Path = storage) -> subprocess.Popen:
            process = spawn_worker(name, _env(folder, server.url), storage, warmup=False)
            workers[name] = process
            deadline = time.time() + 60
            while not any(name in reply for reply in map(str, queue.ping_workers(0.5))):
                assert process.poll() is None and time.time() < deadline, (storage / f"{name}.log").read_text()
            return process

        def stop_worker(name: str, sig: int = signal.SIGTERM) -> None:
            process = workers.pop(name)
            os.killpg(process.pid, sig)
            process.wait(30)

        yield {"client": client, "storage": storage, "settings": settings, "queue": queue, "redis": server,
               "start_worker": start_worker, "stop_worker": stop_worker, "workers": workers}
        for name in list(workers):
            stop_worker(name, signal.SIGKILL)
        server.stop()


@pytest.fixture(scope="module")
def inputs(faults, files):  # noqa: F811 - the fixture imported above
    client = faults["client"]
    ids = {name: upload_character(client, files, name).json()["id"] for name in ("source", "target", "tall")}
    ids["hair"] = (files["dir"] / "hair.data").read_bytes()
    return ids


def hairstyle(client, ids, guides: int):
    return client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": ids["source"],
                                                             "guides": str(guides)},
                       files={"hair": ("groom.data", ids["hair"])})


def retarget(client, body: dict, headers=AUTH):
    return client.post("/v1/retargets", headers=headers, json=body)


def slow_job(hairstyle_id: str, target: str) -> dict:
    return {"hairstyle_id": hairstyle_id, "target_character_ids": [target],
            "options": {"method": "global", "max_iterations": 40, "step_tolerance": 0, "energy_tolerance": 0}}


def job_record(storage: Path, job_id: str) -> dict:
    return json.loads((storage / "records" / "jobs" / f"{job_id}.json").read_text())


def job_files(storage: Path) -> list[str]:
    return sorted(path.name for path in (storage / "records" / "jobs").glob("*.json"))


def log_of(faults, name: str) -> str:
    return (faults["storage"] / f"{name}.log").read_text()


# --------------------------------------------------------------------------------------


def test_a_worker_of_another_deployment_takes_no_task(faults, inputs, tmp_path):
    """A worker on another storage folder (another deployment) on the same Redis: /readyz is not ready, it
    never takes the deployment's tasks, and one put on its queue by hand is refused and sent on."""
    client, queue = faults["client"], faults["queue"]
    faults["start_worker"]("foreign", tmp_path)
    foreign_id = json.loads((tmp_path / "deployment.json").read_text())["id"]
    assert foreign_id != queue.deployment
    ready = client.get("/readyz")
    assert ready.status_code == 503 and ready.json()["checks"] == {"redis": True, "worker": False}
    assert ready.json()["deployment"] == queue.deployment and ready.json()["broker"] == "redis"

    created = hairstyle(client, inputs, 20)
    assert created.status_code == 201, created.text
    inputs["hairstyle"] = created.json()["id"]
    job = retarget(client, {"hairstyle_id": inputs["hairstyle"], "target_character_ids": [inputs["target"]],
                            "options": {"max_iterations": 5}}).json()["jobs"][0]
    # the foreign worker's queue gets a task of this deployment, as a misrouted message would
    from hairport.storage import queue_name
    from hairport.worker.app import RETARGET_TASK

    record = job_record(faults["storage"], job["id"])
    queue.celery.send_task(RETARGET_TASK, args=[job["id"]], kwargs={"deployment": queue.deployment},
                           queue=queue_name(foreign_id, "retarget"), task_id=record["task_id"])
    deadline = time.time() + 30
    while "refused" not in log_of(faults, "foreign"):
        assert time.time() < deadline, log_of(faults, "foreign")
        time.sleep(0.2)
    assert f"belongs to deployment {queue.deployment}" in log_of(faults, "foreign")
    assert client.get(f"/v1/jobs/{job['id']}", headers=AUTH).json()["state"] == "queued"
    assert queue.depths()["retarget"] == 2  # the job's message, and the refused one sent on to this deployment

    faults["start_worker"]("w1")
    assert client.get("/readyz").status_code == 200
    done = wait_for(client, f"/v1/jobs/{job['id']}", lambda b: b["state"] in DONE, JOB_TIMEOUT)
    assert done["state"] == "succeeded" and done["worker"].startswith("w1@"), done
    faults["stop_worker"]("foreign")


def test_a_lost_message_is_sent_again(faults, inputs):
    """Jobs and a preprocessing queued while no worker runs, then Redis restarted empty: the first worker's
    sweeper finds their messages gone and sends them again."""
    client, storage, redis_server = faults["client"], faults["storage"], faults["redis"]
    faults["stop_worker"]("w1")
    variant = hairstyle(client, inputs, 12)
    assert variant.status_code == 201 and variant.json()["preprocessing"]["state"] == "queued"
    jobs = retarget(client, {"hairstyle_id": variant.json()["id"], "target_character_ids": [inputs["target"]],
                             "options": {"max_iterations": 5}}).json()["jobs"]
    task_id = job_record(storage, jobs[0]["id"])["task_id"]
    assert task_id in faults["queue"].task_ids_in_broker()
    redis_server.stop()
    redis_server.start()
    assert faults["queue"].task_ids_in_broker() == set()
    faults["start_worker"]("w1")
    done = wait_for(client, f"/v1/jobs/{jobs[0]['id']}", lambda b: b["state"] in DONE, JOB_TIMEOUT)
    assert done["state"] == "succeeded", done
    record = job_record(storage, jobs[0]["id"])
    assert record["requeues"] == 1 and record["task_id"] != task_id
    assert client.get(f"/v1/hairstyles/{variant.json()['id']}", headers=AUTH).json()["preprocessing"]["state"] == "ready"


def test_redis_down_at_submit_is_503_and_leaves_nothing(faults, inputs):
    client, storage, redis_server = faults["client"], faults["storage"], faults["redis"]
    body = {"hairstyle_id": inputs["hairstyle"], "target_character_ids": [inputs["target"], inputs["tall"]],
            "options": {"max_iterations": 5}}
    headers = {**AUTH, "Idempotency-Key": "outage-1"}
    before = job_files(storage)
    redis_server.stop()
    began = time.monotonic()
    refused = retarget(client, body, headers)
    seconds = time.monotonic() - began
    problem = assert_problem(refused, 503, "queue_unavailable")
    assert int(refused.headers["Retry-After"]) > 0 and "nothing was started" in problem["detail"]
    assert seconds < 20, f"the request waited {seconds:.1f} s for the broker"  # bounded, not the default minutes
    assert job_files(storage) == before
    assert client.get("/v1/jobs", headers=AUTH, params={"state": "queued"}).json()["total"] == 0
    # a new hairstyle variant: its preprocessing claim is released, not left blocking
    variant = hairstyle(client, inputs, 9)
    assert_problem(variant, 503, "queue_unavailable")
    claims = [json.loads(path.read_text()) for path in (storage / "records" / "preprocessing").glob("*.json")]
    assert [claim for claim in claims if claim["state"] == "queued"] == []

    redis_server.start()
    again = retarget(client, body, headers)
    assert again.status_code == 202, again.text
    ids = [job["id"] for job in again.json()["jobs"]]
    assert len(ids) == 2 and len(job_files(storage)) == len(before) + 2
    assert [job["id"] for job in retarget(client, body, headers).json()["jobs"]] == ids  # the replay
    variant = hairstyle(client, inputs, 9)
    assert variant.status_code == 201 and variant.json()["preprocessing"]["state"] in ("queued", "running", "ready")
    for job_id in ids:
        done = wait_for(client, f"/v1/jobs/{job_id}", lambda b: b["state"] in DONE, JOB_TIMEOUT)
        assert done["state"] == "succeeded", done
    ready = wait_for(client, f"/v1/hairstyles/{variant.json()['id']}",
                     lambda b: b["preprocessing"]["state"] in ("ready", "failed"), JOB_TIMEOUT)
    assert ready["preprocessing"]["state"] == "ready"


def test_a_killed_worker_host_makes_its_job_stale_and_another_finishes_it(faults, inputs):
    client = faults["client"]
    faults["start_worker"]("w2")
    job = retarget(client, slow_job(inputs["hairstyle"], inputs["tall"])).json()["jobs"][0]
    running = wait_for(client, f"/v1/jobs/{job['id']}", lambda b: b["state"] == "running" and b["stage"] == "solve")
    assert running["heartbeat_at"] is not None and running["attempts"] == 1
    victim = running["worker"].split("@")[0]
    faults["stop_worker"](victim, signal.SIGKILL)  # the main process and its child: the host is gone
    killed_at = time.time()
    stale = wait_for(client, f"/v1/jobs/{job['id']}", lambda b: b["stale_at"] is not None, STALE_WITHIN_SECONDS)
    assert stale["stale_at"] - killed_at <= STALE_WITHIN_SECONDS
    done = wait_for(client, f"/v1/jobs/{job['id']}", lambda b: b["state"] in DONE, JOB_TIMEOUT)
    assert done["state"] == "succeeded" and done["attempts"] == 2, done
    assert not done["worker"].startswith(f"{victim}@")


def test_a_job_that_kills_its_worker_every_time_ends_worker_lost(faults, inputs):
    """As the OOM killer would: the job's worker child is killed at every start; after max_attempts starts
    the job fails with worker_lost and is not run again."""
    client = faults["client"]
    job = retarget(client, slow_job(inputs["hairstyle"], inputs["target"])).json()["jobs"][0]
    for attempt in (1, 2, 3):
        running = wait_for(client, f"/v1/jobs/{job['id']}",
                           lambda b, n=attempt: b["state"] == "running" and b["attempts"] == n, JOB_TIMEOUT)
        pid = job_record(faults["storage"], job["id"])["worker_pid"]
        os.kill(pid, signal.SIGKILL)
    failed = wait_for(client, f"/v1/jobs/{job['id']}", lambda b: b["state"] in DONE, JOB_TIMEOUT)
    assert failed["state"] == "failed" and failed["error"]["code"] == "worker_lost", failed
    assert failed["attempts"] == 3 and "died 3 times" in failed["error"]["message"]
    assert running["worker"] == failed["worker"]
    assert all(process.poll() is None for process in faults["workers"].values())  # the worker lives on


def test_cancels_while_redis_is_down_apply_whole_and_no_worker_runs_the_jobs(faults, inputs, tmp_path):
    """Redis down: DELETE of a job and of a batch of two, sent to a real server, answer 200 with every job
    cancelled, as the records say: a worker reads a job's record before it starts it, so revoking the messages
    is only a saving, logged when the broker is away. Redis back with the messages it held: a worker receives
    them and starts none of those jobs, then runs a job sent after them."""
    import httpx

    client, storage, redis_server, queue = faults["client"], faults["storage"], faults["redis"], faults["queue"]
    for name in list(faults["workers"]):
        faults["stop_worker"](name)  # the jobs wait in the queue until the outage
    hairstyle_id = inputs.get("hairstyle") or hairstyle(client, inputs, 20).json()["id"]
    port = free_port()
    server = spawn_server(_env(storage, redis_server.url), port, tmp_path)
    try:
        http = httpx.Client(base_url=f"http://127.0.0.1:{port}", headers=AUTH, timeout=60)
        deadline = time.monotonic() + 60
        while True:
            try:
                if http.get("/healthz").status_code == 200:
                    break
            except httpx.HTTPError:
                assert server.poll() is None and time.monotonic() < deadline, (tmp_path / "serve.log").read_text()
                time.sleep(0.2)
        options = {"options": {"max_iterations": 5}}
        job = retarget(http, {"hairstyle_id": hairstyle_id, "target_character_ids": [inputs["target"]], **options})
        batch = http.post("/v1/batches", json={"hairstyle_ids": [hairstyle_id], **options,
                                               "target_character_ids": [inputs["target"], inputs["tall"]]})
        assert (job.status_code, batch.status_code) == (202, 202), (job.text, batch.text)
        ids = [job.json()["jobs"][0]["id"], *(pair["id"] for pair in batch.json()["jobs"])]
        task_ids = {job_record(storage, job_id)["task_id"] for job_id in ids}
        assert len(task_ids) == 3 and task_ids <= queue.task_ids_in_broker()

        redis_server.stop(keep=True)
        cancelled = http.delete(f"/v1/jobs/{ids[0]}")
        assert cancelled.status_code == 200 and cancelled.json()["state"] == "cancelled", cancelled.text
        batch_cancelled = http.delete(f"/v1/batches/{batch.json()['id']}")
        assert batch_cancelled.status_code == 200, batch_cancelled.text
        assert [pair["state"] for pair in batch_cancelled.json()["jobs"]] == ["cancelled", "cancelled"]
        assert batch_cancelled.json()["state"] == "done" and batch_cancelled.json()["counts"]["cancelled"] == 2
        records = [job_record(storage, job_id) for job_id in ids]
        assert [(record["state"], record["cancel_requested"]) for record in records] == [("cancelled", True)] * 3
        assert (tmp_path / "serve.log").read_text().count("not revoked") == 2  # one try per request, logged

        redis_server.start()
        assert task_ids <= queue.task_ids_in_broker()  # the messages are back, never revoked
        faults["start_worker"]("w3")
        deadline = time.monotonic() + JOB_TIMEOUT
        while task_ids & queue.task_ids_in_broker():  # delivered, and acknowledged once their task returned
            assert time.monotonic() < deadline, "the worker did not take the messages"
            time.sleep(0.2)
        after = retarget(http, {"hairstyle_id": hairstyle_id, "target_character_ids": [inputs["target"]], **options})
        done = wait_for(http, f"/v1/jobs/{after.json()['jobs'][0]['id']}", lambda b: b["state"] in DONE, JOB_TIMEOUT)
        assert done["state"] == "succeeded", done
        # the cancelled jobs' records are as the cancel left them: no worker started them
        assert [job_record(storage, job_id) for job_id in ids] == records
        assert all(record["attempts"] == 0 and record["started_at"] is None for record in records)
    finally:
        stop(server)
