"""Hosts that share nothing but URLs: records in PostgreSQL, blobs in an S3-compatible server (SeaweedFS), both
started by the tests; the API in-process and two ``hairport worker`` processes, each with a storage folder of
its own (its cache), so no folder is shared by any two of them.

A 400-strand groom with 20 guides on the toy characters, chunks of at most 3,000 particles: one job's fine level
is six chunk tasks over both workers (also with one of them killed in the middle of a chunk); a 2 x 3 batch runs
across them too; a served API with a cache of its own drives the dashboard; the store crashes under an upload and
stops under the API.
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
from contextlib import contextmanager

import httpx
import numpy as np
import pytest

from hairport.storage.s3 import PART_BYTES
from tests.hairport.storage.test_postgres import fresh_database
from tests.servers.fixtures import postgres_server, postgres_url  # noqa: F401
from tests.servers.seaweed import SeaweedServer

from .deployment import in_process_app, kill_workers, service_env, spawn_worker, wait_for_workers
from .test_service_api import AUTH, upload_character, wait_for

CHUNK_PARTICLES = 3_000
#: iterations of the job whose chunk is killed (the options' most): a chunk runs for seconds (at 300 it took half
#: a second, sometimes over before a poll saw it running)
CHUNK_KILL_ITERATIONS = 1_000
#: two-point strands of the upload the store is killed under: a 17 MB ``.data`` file, three parts
LARGE_UPLOAD_STRANDS = 600_000
SLOW = {"method": "multiscale", "step_tolerance": 0, "energy_tolerance": 0, "max_iterations": 60}
PERIODS = dict(HAIRPORT_HEARTBEAT_SECONDS="1", HAIRPORT_STALE_AFTER_SECONDS="8", HAIRPORT_SWEEP_SECONDS="2",
               HAIRPORT_LOST_AFTER_SECONDS="30", HAIRPORT_FINE_CHUNK_PARTICLES=str(CHUNK_PARTICLES))
JOB_TIMEOUT = 300
DONE = ("succeeded", "failed", "cancelled")
HOSTS = ("host1", "host2")


@pytest.fixture(scope="module")
def seaweed():
    with SeaweedServer() as server:
        yield server


@contextmanager
def url_deployment(tmp_path_factory, redis_url: str, database_server_url: str, seaweed, prefix: str,
                   hosts: tuple[str, ...], periods: dict):
    """An in-process API and a worker per name of ``hosts``, each with a cache folder of its own, their records in
    a new database of ``database_server_url``'s server and their blobs under ``prefix`` of the SeaweedFS bucket:
    ``{"client", "folders", "settings", "workers", "shared"}`` (``shared``: the ``HAIRPORT_`` settings every host
    has, its cache folder aside)."""
    endpoint, access_key, secret_key, bucket = seaweed.endpoint
    shared = dict(periods, HAIRPORT_DATABASE_URL=fresh_database(database_server_url),
                  HAIRPORT_STORAGE_URL=f"s3://{bucket}/{prefix}", HAIRPORT_S3_ENDPOINT_URL=endpoint,
                  HAIRPORT_S3_ACCESS_KEY_ID=access_key, HAIRPORT_S3_SECRET_ACCESS_KEY=secret_key,
                  HAIRPORT_S3_REGION="us-east-1")
    folders = {name: tmp_path_factory.mktemp(f"{name}-cache") for name in ("api", *hosts)}
    workers = {name: spawn_worker(name, service_env(folders[name], redis_url, **shared), folders[name], warmup=False)
               for name in hosts}
    try:
        with in_process_app(service_env(folders["api"], redis_url, **shared)) as (settings, queue, client):
            wait_for_workers(queue, workers, {name: folders[name] / f"{name}.log" for name in workers})
            yield {"client": client, "folders": folders, "settings": settings, "workers": workers, "shared": shared}
    finally:
        kill_workers(workers)


@pytest.fixture(scope="module")
def hosts(tmp_path_factory, redis_url, postgres_url, seaweed):  # noqa: F811
    with url_deployment(tmp_path_factory, redis_url, postgres_url, seaweed, "multihost", HOSTS, PERIODS) as deployment:
        yield deployment


@pytest.fixture(scope="module")
def inputs(hosts, tmp_path_factory):
    from hairport.solver.io.hair import write_hair
    from hairport.solver.synthetic import toy
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import write_character

    folder = tmp_path_factory.mktemp("multihost-inputs")
    source = toy.toy_character(name="source")
    targets = {"target": toy.toy_character(head_scale=(1.1, 0.95, 1.05), neck_length=0.15, shoulder_width=0.42,
                                           name="target"),
               "wide": toy.toy_character(head_scale=(1.2, 1.0, 1.1), shoulder_width=0.48, name="wide"),
               "slim": toy.toy_character(head_scale=(0.95, 1.0, 0.95), shoulder_width=0.36, name="slim")}
    for name, character in (("source", source), *targets.items()):
        write_character(character, folder / f"{name}.obj", folder / f"{name}.skeleton.json")
    client = hosts["client"]
    ids = {name: upload_character(client, {"dir": folder}, name).json()["id"] for name in ("source", *targets)}
    for name, strands in (("long", 400), ("short", 60)):
        write_hair(folder / f"{name}.data", generate_groom(source, "long" if name == "long" else "short", strands, 40,
                                                           seed=3))
        response = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": ids["source"],
                                                                     "guides": "20"},
                               files={"hair": (f"{name}.data", (folder / f"{name}.data").read_bytes())})
        assert response.status_code == 201, response.text
        ids[name] = response.json()["id"]
    return ids


def job_record(hosts, job_id: str):
    from hairport.repository import Repository
    from hairport.storage import open_storage

    return Repository(open_storage(hosts["settings"])).job(job_id)


def single_process_points(hosts, job) -> np.ndarray:
    """The job's result as one process computes it (the stored artifact and target, read through the URLs)."""
    from hairport import solver
    from hairport.records import ArtifactRecord
    from hairport.repository import Repository
    from hairport.storage import open_storage
    from hairport.worker.loading import job_inputs

    repository = Repository(open_storage(hosts["settings"]))
    artifact = repository.get(ArtifactRecord, job.artifact_key)
    adaptable, target, target_input = job_inputs(repository, hosts["settings"], job, artifact)
    result = solver.retarget(adaptable, target, solver.RetargetOptions(**job.options), target_input=target_input)
    return solver.hair_in_frame(adaptable.frame, result.hair).points


def result_points(hosts, job_id: str, tmp_path) -> np.ndarray:
    from hairport import solver

    response = hosts["client"].get(f"/v1/jobs/{job_id}/result", headers=AUTH, params={"format": "npz"})
    assert response.status_code == 200
    path = tmp_path / f"{job_id}.npz"
    path.write_bytes(response.content)
    return solver.read_hair(path).points


def test_one_job_spreads_over_two_hosts_that_share_no_folder_and_equals_one_process(hosts, inputs, tmp_path):
    client = hosts["client"]
    response = client.post("/v1/retargets", headers=AUTH, json={
        "hairstyle_id": inputs["long"], "target_character_ids": [inputs["target"]], "options": SLOW})
    assert response.status_code == 202, response.text
    job_id = response.json()["jobs"][0]["id"]
    done = wait_for(client, f"/v1/jobs/{job_id}", lambda body: body["state"] in DONE, JOB_TIMEOUT)
    assert done["state"] == "succeeded", done
    job = job_record(hosts, job_id)
    assert len(job.fine.chunks) == 6 and all(chunk.state == "done" for chunk in job.fine.chunks)
    assert {chunk.worker.split("@")[0] for chunk in job.fine.chunks} == set(HOSTS), job.fine.chunks
    assert done["metrics"]["penetrating_particles"] == 0
    assert np.array_equal(result_points(hosts, job_id, tmp_path), single_process_points(hosts, job))
    # no record and no index in any folder: they are in the database; the folders hold caches only, and every
    # blob a host has is in the object store (the result, the chunks' points and inputs among them)
    from hairport.storage import open_storage

    store = open_storage(hosts["settings"]).remote
    assert store.url.startswith("s3://")
    stored = {info.key.rsplit("/", 1)[-1] for info in store.list("blobs/")}
    assert f"{job.outputs['npz'].sha256}.npz" in stored and f"{job.fine.inputs}.npz" in stored
    for name, folder in hosts["folders"].items():
        assert not any((folder / "records").glob("*/*.json")), name
        assert not (folder / "index" / "records.sqlite3").exists(), name
        cached = {path.name for path in (folder / "blobs").glob("*/*")}
        assert cached and cached <= stored, name


def test_a_two_by_three_batch_runs_across_the_hosts(hosts, inputs):
    client = hosts["client"]
    response = client.post("/v1/batches", headers=AUTH, json={
        "hairstyle_ids": [inputs["long"], inputs["short"]],
        "target_character_ids": [inputs["target"], inputs["wide"], inputs["slim"]],
        "options": {"max_iterations": 10}, "output_format": "npz"})
    assert response.status_code == 202, response.text
    batch_id = response.json()["id"]
    done = wait_for(client, f"/v1/batches/{batch_id}", lambda body: body["state"] == "done", JOB_TIMEOUT)
    assert done["counts"]["succeeded"] == 6, done
    jobs = [job_record(hosts, job["id"]) for job in done["jobs"]]
    assert len(jobs) == 6 and {job.worker.split("@")[0] for job in jobs} == set(HOSTS)
    assert all(job.metrics["penetrating_particles"] == 0 for job in jobs)
    archive = client.get(f"/v1/batches/{batch_id}/results", headers=AUTH)
    assert archive.status_code == 200 and archive.content[:2] == b"PK"


def test_a_worker_killed_during_a_chunk_on_the_other_host_costs_that_chunk_only(hosts, inputs):
    client = hosts["client"]
    response = client.post("/v1/retargets", headers=AUTH, json={
        "hairstyle_id": inputs["long"], "target_character_ids": [inputs["target"]],
        "options": {**SLOW, "max_iterations": CHUNK_KILL_ITERATIONS}})
    assert response.status_code == 202, response.text
    job_id = response.json()["jobs"][0]["id"]
    deadline = time.monotonic() + JOB_TIMEOUT
    victim = None
    while victim is None:
        job = job_record(hosts, job_id)
        assert time.monotonic() < deadline and job.state in ("queued", "running"), job
        chunks = job.fine.chunks if job.fine else []
        victim = next((chunk for chunk in chunks if chunk.state == "running"
                       and chunk.worker_pid not in (None, job.worker_pid)
                       and chunk.worker.split("@")[0] != job.worker.split("@")[0]), None)
        time.sleep(0.05)
    os.kill(victim.worker_pid, signal.SIGKILL)  # the pool child solving the chunk on the other host
    done = wait_for(client, f"/v1/jobs/{job_id}", lambda body: body["state"] in DONE, JOB_TIMEOUT)
    assert done["state"] == "succeeded", done
    job = job_record(hosts, job_id)
    attempts = {chunk.index: chunk.attempts for chunk in job.fine.chunks}
    assert attempts[victim.index] == 2, job.fine
    assert all(count == 1 for index, count in attempts.items() if index != victim.index), attempts
    assert job.attempts == 1 and done["metrics"]["penetrating_particles"] == 0
    assert all(process.poll() is None for process in hosts["workers"].values())  # both workers live on


def test_the_dashboard_works_against_the_hosts(hosts, inputs, redis_url, tmp_path_factory):
    """A served API with a cache of its own: a job is listed and drawn in the viewer, and its result downloads
    byte for byte through the page."""
    from tests.conftest import free_port
    from tests.integration.browser import chromium, count_near, count_red, pixels
    from tests.integration.test_dashboard import RESULT_RGB, enter_key, shot

    from .deployment import KEY, spawn_server, stop

    folder = tmp_path_factory.mktemp("multihost-served")
    port = free_port()
    server = spawn_server(service_env(folder, redis_url, **hosts["shared"]), port, folder)
    base = f"http://127.0.0.1:{port}"
    try:
        api = httpx.Client(base_url=base, headers={"X-API-Key": KEY}, timeout=30)
        deadline = time.monotonic() + 60
        while True:
            with contextlib.suppress(httpx.HTTPError):
                if api.get("/readyz").status_code == 200:
                    break
            assert server.poll() is None and time.monotonic() < deadline, (folder / "serve.log").read_text()[-2000:]
            time.sleep(0.3)
        response = api.post("/v1/retargets", json={"hairstyle_id": inputs["short"],
                                                   "target_character_ids": [inputs["wide"]],
                                                   "options": {"max_iterations": 10}})
        assert response.status_code == 202, response.text
        job_id = response.json()["jobs"][0]["id"]
        done = wait_for(hosts["client"], f"/v1/jobs/{job_id}", lambda body: body["state"] in DONE, JOB_TIMEOUT)
        assert done["state"] == "succeeded", done
        crossing = done["metrics"]["crossing_segments"]["count"]
        with chromium() as page:
            enter_key(page, base, KEY)
            page.wait_for_selector("#key-state:text('key accepted')")
            page.goto(f"{base}/ui/#/characters")
            for name in ("source", "target", "wide", "slim"):
                page.wait_for_selector(f"#characters tr[data-id='{inputs[name]}']")
            page.goto(f"{base}/ui/#/view/{job_id}")
            page.wait_for_selector("#viewer[data-loaded=true]", timeout=60_000)
            stats = page.inner_text("#viewer-stats")
            assert "60 of 60 strands" in stats and f"{crossing:,} drawn segments through it" in stats, stats
            page.set_checked("input[name=show-body]", False)
            page.wait_for_timeout(400)
            strands = pixels(shot(page, "multihost-viewer", "#viewer"))
            assert count_near(strands, RESULT_RGB, 12) > 100 and (count_red(strands) > 0) == (crossing > 0)
            page.goto(f"{base}/ui/#/jobs/{job_id}")
            with page.expect_download() as download:
                page.click("#downloads button[data-format=obj]")
            path = folder / "result.obj"
            download.value.save_as(path)
            assert path.read_bytes() == api.get(f"/v1/jobs/{job_id}/result", params={"format": "obj"}).content
            assert page.errors == []
    finally:
        stop(server)


def test_an_upload_cut_off_by_the_store_crashing_is_refused_whole(hosts, inputs, seaweed, tmp_path_factory):
    """The store killed while the API writes a large upload into it (a multipart upload in progress): 503, no
    record, no object; started again, the same upload is stored."""
    from hairport.repository import Repository
    from hairport.solver.io.hair import write_hair
    from hairport.solver.synthetic import toy
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.storage import open_storage

    client = hosts["client"]
    folder = tmp_path_factory.mktemp("multihost-cut")
    write_hair(folder / "large.data", generate_groom(toy.toy_character(name="source"), "short", LARGE_UPLOAD_STRANDS,
                                                     2, seed=5))
    data = (folder / "large.data").read_bytes()
    assert len(data) > 2 * PART_BYTES  # a multipart upload
    repository = Repository(open_storage(hosts["settings"]))
    store = repository.storage.remote
    before_records = len(list(repository.storage.list_records("hairstyles")))
    before_objects = {info.key for info in store.list("blobs/")}
    answers = []

    def upload():
        answers.append(client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": inputs["source"]},
                                   files={"hair": ("large.data", data)}))

    uploading = threading.Thread(target=upload)
    uploading.start()
    try:
        deadline = time.monotonic() + 60
        while not seaweed.multipart_uploads():
            assert time.monotonic() < deadline and uploading.is_alive(), answers
            time.sleep(0.005)
        seaweed.kill()
        uploading.join(timeout=120)
        assert not uploading.is_alive()
    finally:
        seaweed.start()
    response = answers[0]
    assert response.status_code == 503 and response.json()["code"] == "storage_unavailable", response.text
    assert len(list(repository.storage.list_records("hairstyles"))) == before_records
    assert {info.key for info in store.list("blobs/")} == before_objects
    response = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": inputs["source"]},
                           files={"hair": ("large.data", data)})
    assert response.status_code == 201, response.text


def test_with_the_object_store_down_the_api_answers_503_keeps_nothing_and_recovers(hosts, inputs, seaweed,
                                                                                   tmp_path_factory):
    """Last in the module: it stops the store (and starts it again)."""
    from hairport.repository import Repository
    from hairport.solver.synthetic import toy
    from hairport.solver.synthetic.makehuman import write_character
    from hairport.storage import open_storage

    client = hosts["client"]
    folder = tmp_path_factory.mktemp("multihost-fault")
    write_character(toy.toy_character(head_scale=(1.05, 1.0, 1.0), name="new"), folder / "new.obj",
                    folder / "new.skeleton.json")
    repository = Repository(open_storage(hosts["settings"]))
    before = len(list(repository.storage.list_records("characters")))
    seaweed.stop()
    try:
        response = upload_character(client, {"dir": folder}, "new")
        assert response.status_code == 503 and response.json()["code"] == "storage_unavailable", response.text
        assert int(response.headers["Retry-After"]) > 0 and "secret" not in response.text.lower()
        ready = client.get("/readyz")
        assert ready.status_code == 503 and ready.json()["checks"]["storage"] is False
        assert ready.json()["checks"]["database"] is True
        assert len(list(repository.storage.list_records("characters"))) == before  # no record of the refused upload
    finally:
        seaweed.start()
    response = upload_character(client, {"dir": folder}, "new")
    assert response.status_code == 201, response.text
    assert client.get("/readyz").json()["checks"]["storage"] is True
