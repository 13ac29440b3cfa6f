"""The HTTP API end to end: a real Redis, real Celery worker processes, the FastAPI app.

The worker runs as a separate process (``hairport worker``) against the tests' own Redis
server (``redis_url`` in conftest.py); the API runs in-process through Starlette's test client. Inputs are the
small toy characters and a 60-strand groom, so each job takes a few seconds.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest

from .deployment import KEY, OTHER_KEY, in_process_app, service_env, spawn_worker

AUTH = {"Authorization": f"Bearer {KEY}"}
OTHER = {"X-API-Key": OTHER_KEY}
#: seconds a dead worker's job waits before Redis hands it out again (short for the test)
VISIBILITY_TIMEOUT = 6
#: a dead worker's job is also seen stale by the sweeper within seconds (the defaults take about a minute)
PERIODS = dict(HAIRPORT_HEARTBEAT_SECONDS="1", HAIRPORT_STALE_AFTER_SECONDS="8", HAIRPORT_SWEEP_SECONDS="2")
JOB_TIMEOUT = 240


@pytest.fixture(scope="module")
def service(tmp_path_factory, redis_url):
    """Storage folder, settings, the app, and a started worker process (the environment is
    restored afterwards)."""
    storage = tmp_path_factory.mktemp("service-storage")
    env = service_env(storage, redis_url, HAIRPORT_VISIBILITY_TIMEOUT=str(VISIBILITY_TIMEOUT), **PERIODS)
    with in_process_app(env) as (settings, queue, client):
        yield from _service(storage, env, settings, queue, client)


def _service(storage: Path, env: dict, settings, queue, client):
    workers = []

    def start_worker(name: str) -> subprocess.Popen:
        process = spawn_worker(name, env, storage)
        workers.append((name, process))
        deadline = time.time() + 60
        while time.time() < deadline:
            replies = queue.ping_workers(0.5)
            if any(name in next(iter(reply)) for reply in replies):
                return process
            assert process.poll() is None, (storage / f"{name}.log").read_text()
        raise AssertionError(f"worker {name} did not answer")

    start_worker("w1")
    yield {"client": client, "storage": storage, "settings": settings, "start_worker": start_worker,
           "workers": workers, "queue": queue}
    for _, process in workers:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGTERM)
    for _, process in workers:
        try:
            process.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Toy characters (OBJ + skeleton JSON) and a groom, as bytes."""
    from hairport.solver.io.hair import write_hair
    from hairport.solver.synthetic import toy
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import write_character

    d = tmp_path_factory.mktemp("service-inputs")
    source = toy.toy_character(name="source")
    target = toy.toy_character(head_scale=(1.1, 0.95, 1.05), neck_length=0.15, shoulder_width=0.42, name="target")
    tall = toy.toy_character(head_scale=(0.95, 1.1, 1.0), neck_length=0.13, shoulder_width=0.38, name="tall")
    for name, character in (("source", source), ("target", target), ("tall", tall)):
        write_character(character, d / f"{name}.obj", d / f"{name}.skeleton.json")
    hair = generate_groom(source, "short", 60, 12, seed=0)
    write_hair(d / "hair.data", hair)
    return {"dir": d, "hair": hair}


def upload_character(client, files, name, headers=AUTH):
    d = files["dir"]
    return client.post("/v1/characters", headers=headers, files={
        "mesh": (f"{name}.obj", (d / f"{name}.obj").read_bytes()),
        "skeleton": (f"{name}.skeleton.json", (d / f"{name}.skeleton.json").read_bytes()),
    })


@pytest.fixture(scope="module")
def uploaded(service, files):
    client = service["client"]
    ids = {}
    for name in ("source", "target", "tall"):
        response = upload_character(client, files, name)
        assert response.status_code == 201, response.text
        ids[name] = response.json()["id"]
    response = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": ids["source"], "guides": "20"},
                           files={"hair": ("groom.data", (files["dir"] / "hair.data").read_bytes())})
    assert response.status_code == 201, response.text
    ids["hairstyle"] = response.json()["id"]
    return ids


def wait_for(client, path, condition, timeout=JOB_TIMEOUT, headers=AUTH):
    deadline = time.time() + timeout
    while True:
        body = client.get(path, headers=headers).json()
        if condition(body):
            return body
        assert time.time() < deadline, f"timed out waiting on {path}: {body}"
        time.sleep(0.25)


def assert_problem(response, status, code):
    assert response.status_code == status, response.text
    assert response.headers["content-type"].startswith("application/problem+json")
    body = response.json()
    assert body["code"] == code and body["status"] == status and body["type"].endswith(code)
    return body


# --------------------------------------------------------------------------------------


def test_health_and_readiness(service):
    client = service["client"]
    assert client.get("/healthz").json() == {"status": "ok"}
    ready = client.get("/readyz")
    assert ready.status_code == 200 and ready.json()["checks"] == {"redis": True, "worker": True}


def test_requests_without_a_valid_key_are_refused(service):
    client = service["client"]
    assert_problem(client.get("/v1/jobs"), 401, "unauthorized")
    assert_problem(client.get("/v1/jobs", headers={"Authorization": "Bearer nope"}), 401, "unauthorized")
    assert client.get("/v1/jobs", headers=OTHER).status_code == 200


def test_character_upload_is_content_addressed(service, files, uploaded):
    client = service["client"]
    again = upload_character(client, files, "source")
    assert again.status_code == 201 and again.json()["id"] == uploaded["source"]
    body = again.json()
    assert body["vertices"] == 3842 and body["faces"] > 7000 and "head" in body["bones"]
    assert len(body["sha256"]) == 64
    # another key uploading the same bytes gets its own id and cannot see the first
    theirs = upload_character(client, files, "source", headers=OTHER).json()["id"]
    assert theirs != uploaded["source"]
    assert_problem(client.get(f"/v1/characters/{uploaded['source']}", headers=OTHER), 404, "not_found")


def test_bad_character_uploads(service, files):
    client = service["client"]
    obj = (files["dir"] / "source.obj").read_bytes()
    assert_problem(client.post("/v1/characters", headers=AUTH, files={"mesh": ("body.stl", obj)}), 415, "unknown_format")
    truncated = obj[: len(obj) // 3].rsplit(b"\n", 1)[0] + b"\nf 1 2 999999\n"
    body = assert_problem(client.post("/v1/characters", headers=AUTH, files={"mesh": ("body.obj", truncated)}), 422,
                          "bad_faces")
    assert "mesh" in body["detail"]
    assert_problem(client.post("/v1/characters", headers=AUTH, files={"mesh": ("body.obj", obj)}, data={"units": "ft"}),
                   422, "bad_units")


def test_oversized_upload_is_413_and_stores_nothing(service, files):
    from fastapi.testclient import TestClient

    from hairport.service.app import create_app

    small = TestClient(create_app(service["settings"].model_copy(update={"max_upload_bytes": 10_000})))
    # meshes only: the worker may store a hairstyle's artifact meanwhile (another test's upload)
    blobs_before = sorted((service["storage"] / "blobs").rglob("*.obj"))
    response = small.post("/v1/characters", headers=AUTH,
                          files={"mesh": ("body.obj", (files["dir"] / "source.obj").read_bytes())})
    body = assert_problem(response, 413, "upload_too_large")
    assert "10,000" in body["detail"]
    assert sorted((service["storage"] / "blobs").rglob("*.obj")) == blobs_before
    assert sorted((service["storage"] / "tmp").rglob("*")) == []
    # a declared length far over the limit is refused before the body is read
    big = small.post("/v1/characters", headers=AUTH, files={"mesh": ("body.obj", b"v 0 0 0\n" * 50_000)})
    assert_problem(big, 413, "upload_too_large")
    assert "over the upload limit" in big.json()["detail"]


def test_bad_hair_uploads(service, files, uploaded):
    client = service["client"]
    data = (files["dir"] / "hair.data").read_bytes()
    bad = bytearray(data)
    bad[8:12] = np.array([np.nan], dtype=np.float32).tobytes()
    body = assert_problem(client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": uploaded["source"]},
                                      files={"hair": ("nan.data", bytes(bad))}), 422, "non_finite")
    assert "hair" in body["detail"]
    assert_problem(client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": uploaded["source"]},
                               files={"hair": ("cut.data", data[:1000])}), 422, "truncated")
    huge = np.array([2**30], dtype=np.int32).tobytes() + data[4:]
    body = assert_problem(client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": uploaded["source"]},
                                      files={"hair": ("huge.data", huge)}), 422, "truncated")
    assert "1,073,741,824 strands" in body["detail"] and str(service["storage"]) not in body["detail"]
    from fastapi.testclient import TestClient

    from hairport.service.app import create_app

    strict = TestClient(create_app(service["settings"].model_copy(update={"max_strands": 50})))
    body = assert_problem(strict.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": uploaded["source"]},
                                      files={"hair": ("g.data", data)}), 413, "too_large")
    assert "60 strands" in body["detail"] and "50" in body["detail"]
    assert_problem(client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": "0" * 32},
                               files={"hair": ("g.data", data)}), 404, "not_found")
    assert_problem(client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": uploaded["source"]},
                               files={"hair": ("g.fbx", data)}), 415, "unknown_format")


def test_hairstyle_is_preprocessed_once(service, files, uploaded):
    client, storage = service["client"], service["storage"]
    body = wait_for(client, f"/v1/hairstyles/{uploaded['hairstyle']}",
                    lambda b: b["preprocessing"]["state"] in ("ready", "failed"))
    assert body["preprocessing"]["state"] == "ready", body
    assert (body["strands"], body["particles"]) == (60, 720)
    artifacts = sorted((storage / "blobs").rglob("*.hpa"))
    assert len(artifacts) == 1
    again = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": uploaded["source"], "guides": "20"},
                        files={"hair": ("same-bytes.data", (files["dir"] / "hair.data").read_bytes())})
    assert again.status_code == 201
    assert again.json()["id"] == uploaded["hairstyle"] and again.json()["preprocessing"]["state"] == "ready"
    assert sorted((storage / "blobs").rglob("*.hpa")) == artifacts


def test_retarget_onto_two_targets(service, files, uploaded):
    client = service["client"]
    response = client.post("/v1/retargets", headers=AUTH, json={
        "hairstyle_id": uploaded["hairstyle"], "target_character_ids": [uploaded["target"], uploaded["tall"]],
        "options": {"max_iterations": 10}, "output_format": "ply",
    })
    assert response.status_code == 202, response.text
    created = response.json()["jobs"]
    assert len(created) == 2 and response.headers["location"] == f"/v1/jobs/{created[0]['id']}"
    assert {job["state"] for job in created} <= {"queued", "running"}
    for job in created:
        done = wait_for(client, f"/v1/jobs/{job['id']}", lambda b: b["state"] in ("succeeded", "failed", "cancelled"))
        assert done["state"] == "succeeded", done
        assert done["progress"] == 1.0 and done["metrics"]["penetrating_particles"] == 0
        assert done["metrics"]["root_to_target_max"] < 1e-9
        assert done["timings"]["solve"] > 0 and done["metrics"]["method"] == "multiscale"
        result = client.get(f"/v1/jobs/{job['id']}/result", headers=AUTH)
        assert result.status_code == 200
        from hairport.solver.io.hair import read_hair_bytes

        hair = read_hair_bytes(result.content, "ply")
        assert (hair.n_strands, hair.n_particles) == (60, 720)
        npz = client.get(f"/v1/jobs/{job['id']}/result", headers=AUTH, params={"format": "npz"})
        np.testing.assert_allclose(read_hair_bytes(npz.content, "npz").points, hair.points, atol=1e-6)
        converted = client.get(f"/v1/jobs/{job['id']}/result", headers=AUTH, params={"format": "data"})
        assert read_hair_bytes(converted.content, "data").n_strands == 60
        preview = client.get(f"/v1/jobs/{job['id']}/preview.png", headers=AUTH)
        assert preview.content[:8] == b"\x89PNG\r\n\x1a\n"
        report = client.get(f"/v1/jobs/{job['id']}/report", headers=AUTH).json()
        assert report["metrics"]["particles"] == 720 and report["job"]["id"] == job["id"]
        assert_problem(client.get(f"/v1/jobs/{job['id']}", headers=OTHER), 404, "not_found")
        assert_problem(client.get(f"/v1/jobs/{job['id']}/result", headers=OTHER), 404, "not_found")
    listed = client.get("/v1/jobs", headers=AUTH, params={"state": "succeeded", "limit": 1}).json()
    assert listed["total"] >= 2 and len(listed["jobs"]) == 1 and listed["next_offset"] == 1
    assert client.get("/v1/jobs", headers=OTHER, params={"state": "succeeded"}).json()["total"] == 0


def test_other_guide_count_preprocesses_a_cached_variant(service, uploaded):
    client, storage = service["client"], service["storage"]
    # the hairstyle's own artifact first, so that the count below sees only the variant's
    wait_for(client, f"/v1/hairstyles/{uploaded['hairstyle']}", lambda b: b["preprocessing"]["state"] == "ready")
    before = len(list((storage / "blobs").rglob("*.hpa")))
    request = {"hairstyle_id": uploaded["hairstyle"], "target_character_ids": [uploaded["target"]],
               "options": {"guides": 10, "max_iterations": 3}}
    first = client.post("/v1/retargets", headers=AUTH, json=request).json()["jobs"][0]
    done = wait_for(client, f"/v1/jobs/{first['id']}", lambda b: b["state"] in ("succeeded", "failed"))
    assert done["state"] == "succeeded", done
    report = client.get(f"/v1/jobs/{first['id']}/report", headers=AUTH).json()
    assert report["solver"]["guides"] == 10
    assert len(list((storage / "blobs").rglob("*.hpa"))) == before + 1
    second = client.post("/v1/retargets", headers=AUTH, json=request).json()["jobs"][0]
    assert wait_for(client, f"/v1/jobs/{second['id']}", lambda b: b["state"] in ("succeeded", "failed"))["state"] == \
        "succeeded"
    assert len(list((storage / "blobs").rglob("*.hpa"))) == before + 1
    assert_problem(client.post("/v1/retargets", headers=AUTH, json={**request, "options": {"guides": 0}}), 422,
                   "bad_option")


def test_idempotency_key_replays_and_refuses_changes(service, uploaded):
    client = service["client"]
    request = {"hairstyle_id": uploaded["hairstyle"], "target_character_ids": [uploaded["target"]],
               "options": {"max_iterations": 3}}
    headers = {**AUTH, "Idempotency-Key": "retry-42"}
    first = client.post("/v1/retargets", headers=headers, json=request)
    second = client.post("/v1/retargets", headers=headers, json=request)
    assert first.status_code == second.status_code == 202
    assert [j["id"] for j in first.json()["jobs"]] == [j["id"] for j in second.json()["jobs"]]
    changed = client.post("/v1/retargets", headers=headers, json={**request, "output_format": "hair"})
    assert_problem(changed, 422, "idempotency_conflict")


def test_bad_retarget_requests(service, uploaded):
    client = service["client"]
    base = {"hairstyle_id": uploaded["hairstyle"], "target_character_ids": [uploaded["target"]]}
    assert_problem(client.post("/v1/retargets", headers=AUTH, json={**base, "options": {"method": "magic"}}), 422,
                   "unknown_method")
    assert_problem(client.post("/v1/retargets", headers=AUTH, json={**base, "options": {"alpha": -1}}), 422,
                   "bad_option")
    assert_problem(client.post("/v1/retargets", headers=AUTH, json={**base, "output_format": "fbx"}), 422,
                   "invalid_request")
    assert_problem(client.post("/v1/retargets", headers=AUTH, json={**base, "target_character_ids": []}), 422,
                   "invalid_request")
    assert_problem(client.post("/v1/retargets", headers=OTHER, json=base), 404, "not_found")
    for hairline, code in [
        ({"preset": "mohawk"}, "invalid_request"),
        ({"preset": "round", "amount": 1.5}, "invalid_request"),
        ({"preset": "round", "method": "spline"}, "invalid_request"),
        ({}, "bad_option"),
        ({"preset": "round", "curve": {"points": [[0, 0, 0], [1, 0, 0], [0, 1, 0]]}}, "bad_option"),
        ({"curve": {"points": [[0, 0, 0], [1, 0, 0]]}}, "invalid_request"),
        ({"curve": {"points": [[0, 0, 0], [0, 0, 0], [1, 0, 0]]}}, "bad_curve"),
        ({"curve": {"points": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "turning_points": [2, 1]}}, "bad_curve"),
    ]:
        body = assert_problem(client.post("/v1/retargets", headers=AUTH, json={**base, "hairline": hairline}),
                              422, code)
        assert "hairline" in body["detail"], body
    # the toy groom does not reach the ears: the job fails with the reason, nothing else does
    job = client.post("/v1/retargets", headers=AUTH, json={**base, "hairline": {"preset": "straight"}}).json()
    failed = wait_for(client, f"/v1/jobs/{job['jobs'][0]['id']}", lambda b: b["state"] in ("succeeded", "failed"))
    assert failed["state"] == "failed" and failed["error"]["code"] == "bad_scalp", failed
    assert "ear" in failed["error"]["message"]


def test_hairline_edit_jobs(service, tmp_path):
    """A preset and a drawn curve on MakeHuman characters, through the queue."""
    from hairport.solver.io.hair import read_hair_bytes, write_hair
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import PRESETS, build_character, write_character

    client = service["client"]
    ids = {}
    for name in ("average-female", "heavy-male"):
        character = build_character(PRESETS[name])
        write_character(character, tmp_path / f"{name}.obj", tmp_path / f"{name}.skeleton.json")
        response = client.post("/v1/characters", headers=AUTH, files={
            "mesh": (f"{name}.obj", (tmp_path / f"{name}.obj").read_bytes()),
            "skeleton": (f"{name}.skeleton.json", (tmp_path / f"{name}.skeleton.json").read_bytes()),
        })
        assert response.status_code == 201, response.text
        ids[name] = response.json()["id"]
        if name == "average-female":
            write_hair(tmp_path / "short.data", generate_groom(character, "short", 80, 6, seed=3))
    response = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": ids["average-female"],
                                                                 "guides": "20"},
                           files={"hair": ("short.data", (tmp_path / "short.data").read_bytes())})
    assert response.status_code == 201, response.text
    base = {"hairstyle_id": response.json()["id"], "target_character_ids": [ids["heavy-male"]],
            "options": {"max_iterations": 10}}
    preset = client.post("/v1/retargets", headers=AUTH, json={**base, "hairline": {
        "preset": "widows-peak", "amount": 0.7}}).json()["jobs"][0]
    done = wait_for(client, f"/v1/jobs/{preset['id']}", lambda b: b["state"] in ("succeeded", "failed"))
    assert done["state"] == "succeeded", done
    hairline = done["metrics"]["hairline"]
    assert hairline["edit"] == "widows-peak:0.7" and hairline["method"] == "membrane"
    assert hairline["roots_moved"] > 0 and 0.0 < hairline["density_change_l1"] < 0.5
    assert done["metrics"]["penetrating_particles"] == 0 and done["timings"]["hairline"] > 0
    result = read_hair_bytes(client.get(f"/v1/jobs/{preset['id']}/result", headers=AUTH,
                                        params={"format": "npz"}).content, "npz")
    assert result.n_strands == 80
    # a drawn curve far from the head fails its job with the reason
    curve = {"units": "m", "points": [[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.2, 0.0, 0.0]]}
    far = client.post("/v1/retargets", headers=AUTH, json={**base, "hairline": {"curve": curve}}).json()["jobs"][0]
    failed = wait_for(client, f"/v1/jobs/{far['id']}", lambda b: b["state"] in ("succeeded", "failed"))
    assert failed["state"] == "failed" and failed["error"]["code"] == "off_head", failed


def test_bad_target_fails_its_job_and_the_worker_lives_on(service, files, uploaded):
    client = service["client"]
    from hairport.solver.synthetic import toy
    from hairport.solver.synthetic.makehuman import write_character

    d = files["dir"]
    other = toy.toy_character(name="other", neck_length=0.3)
    # another topology: drop the last face
    from hairport.solver.model.character import Character

    other = Character(other.vertices, other.faces[:-1], other.skeleton, other.weights, "other")
    write_character(other, d / "other.obj", d / "other.skeleton.json")
    other_id = upload_character(client, files, "other").json()["id"]
    bad = client.post("/v1/retargets", headers=AUTH, json={"hairstyle_id": uploaded["hairstyle"],
                                                           "target_character_ids": [other_id, uploaded["target"]],
                                                           "options": {"max_iterations": 3, "wrap": "off"}}).json()["jobs"]
    failed = wait_for(client, f"/v1/jobs/{bad[0]['id']}", lambda b: b["state"] in ("succeeded", "failed"))
    assert failed["state"] == "failed" and failed["error"]["code"] == "topology_mismatch"
    assert "topology" in failed["error"]["message"] and "/blobs/" not in failed["error"]["message"]
    assert "options.wrap off keeps to the source's topology" in failed["error"]["message"]
    assert_problem(client.get(f"/v1/jobs/{bad[0]['id']}/result", headers=AUTH), 409, "job_not_succeeded")
    fine = wait_for(client, f"/v1/jobs/{bad[1]['id']}", lambda b: b["state"] in ("succeeded", "failed"))
    assert fine["state"] == "succeeded"
    # by default the source body is wrapped onto it (its axes stated: the toy's head looks alike both ways)
    response = client.post("/v1/characters", headers=AUTH, data={"up_axis": "y", "front_axis": "z"}, files={
        "mesh": ("other.obj", (d / "other.obj").read_bytes()),
        "skeleton": ("other.skeleton.json", (d / "other.skeleton.json").read_bytes())})
    wrapped = client.post("/v1/retargets", headers=AUTH, json={
        "hairstyle_id": uploaded["hairstyle"], "target_character_ids": [response.json()["id"]],
        "options": {"max_iterations": 3}}).json()["jobs"][0]
    done = wait_for(client, f"/v1/jobs/{wrapped['id']}", lambda b: b["state"] in ("succeeded", "failed"))
    assert done["state"] == "succeeded", done
    assert done["metrics"]["penetrating_particles"] == 0 and done["metrics"]["wrap"]["residual_m"]["mean"] < 1e-3
    assert done["timings"]["wrap"] > 0 and done["metrics"]["input"]["target"]["topology"] == "other"


def _slow_job(client, uploaded):
    return client.post("/v1/retargets", headers=AUTH, json={
        "hairstyle_id": uploaded["hairstyle"], "target_character_ids": [uploaded["tall"]],
        "options": {"method": "global", "qp_backend": "osqp", "max_iterations": 1000, "step_tolerance": 0,
                    "eps_c": 0.004}}).json()["jobs"][0]["id"]


def test_cancel_a_running_job(service, uploaded):
    client = service["client"]
    job_id = _slow_job(client, uploaded)
    wait_for(client, f"/v1/jobs/{job_id}", lambda b: b["state"] == "running" and b["stage"] == "solve")
    assert client.delete(f"/v1/jobs/{job_id}", headers=AUTH).status_code == 200
    done = wait_for(client, f"/v1/jobs/{job_id}", lambda b: b["state"] in ("cancelled", "succeeded", "failed"), 60)
    assert done["state"] == "cancelled"
    assert_problem(client.get(f"/v1/jobs/{job_id}/result", headers=AUTH), 409, "job_not_succeeded")


def test_a_job_survives_its_worker_dying(service, uploaded):
    """SIGKILL the worker running a job: Redis hands the job to another worker, which finishes it."""
    client = service["client"]
    spare = service["start_worker"]("w2")
    job_id = client.post("/v1/retargets", headers=AUTH, json={
        "hairstyle_id": uploaded["hairstyle"], "target_character_ids": [uploaded["tall"]],
        "options": {"method": "global", "max_iterations": 40, "step_tolerance": 0, "energy_tolerance": 0}}).json()["jobs"][0]["id"]
    running = wait_for(client, f"/v1/jobs/{job_id}", lambda b: b["state"] == "running" and b["stage"] == "solve")
    by_name = dict(service["workers"])
    victim = by_name[running["worker"].split("@")[0]]
    os.killpg(victim.pid, signal.SIGKILL)
    victim.wait(10)
    survivors = [p for p in by_name.values() if p.poll() is None]
    assert len(survivors) == 1 and spare.poll() is None or by_name["w1"].poll() is None
    done = wait_for(client, f"/v1/jobs/{job_id}", lambda b: b["state"] in ("succeeded", "failed"),
                    JOB_TIMEOUT + VISIBILITY_TIMEOUT)
    assert done["state"] == "succeeded", done
    assert done["attempts"] == 2


def test_metrics_count_jobs_by_state(service, uploaded):
    text = service["client"].get("/metrics").text
    succeeded = [line for line in text.splitlines() if line.startswith('hairport_jobs{state="succeeded"}')]
    assert succeeded and float(succeeded[0].split()[-1]) >= 3
    assert 'hairport_queue_depth{queue="retarget"}' in text
    assert 'hairport_stage_seconds_sum{stage="solve"}' in text


def test_usd_characters_and_an_alembic_groom_end_to_end(service, tmp_path):
    """USD characters (skinned, cm, Z-up, under an Xform) and an Unreal-convention Alembic groom in the
    stage's frame: uploaded, preprocessed and retargeted by the real worker; the result comes back as Alembic
    with its attributes, and converted to USD in the stage's units and up axis."""
    from pxr import Usd, UsdGeom

    from hairport.solver.io.hair import read_hair_bytes
    from hairport.solver.synthetic import toy
    from hairport.solver.synthetic.groom import generate_groom
    from tests.solver.io.character.usd_samples import Y_UP_TO_Z_UP, write_scene
    from tests.solver.io.hair.abc_samples import UNIFORM, write_groom

    client = service["client"]
    source = toy.toy_character(name="source")
    target = toy.toy_character(head_scale=(1.1, 0.95, 1.05), neck_length=0.15, shoulder_width=0.42, name="target")
    write_scene(tmp_path / "source.usda", source)
    write_scene(tmp_path / "target.usdc", target)
    hair = generate_groom(source, "short", 40, 10, seed=2)
    groups = (np.arange(40) % 3).astype(np.int32)
    flags = (np.arange(40) % 5 == 0).astype(np.int16)
    write_groom(tmp_path / "groom.abc", hair.points @ Y_UP_TO_Z_UP / 0.01, hair.counts,
                params=[("groom_group_id", "OInt32GeomParam", "IntArray", groups, UNIFORM),
                        ("groom_guide", "OInt16GeomParam", "ShortArray", flags, UNIFORM)])
    ids = {}
    for name, file in (("source", "source.usda"), ("target", "target.usdc")):
        response = client.post("/v1/characters", headers=AUTH, files={"mesh": (file, (tmp_path / file).read_bytes())})
        assert response.status_code == 201, response.text
        assert response.json()["units"] == "cm"
        ids[name] = response.json()["id"]
    groom = (tmp_path / "groom.abc").read_bytes()
    assert_problem(client.post("/v1/hairstyles", headers=AUTH, files={"hair": ("groom.abc", groom)},
                               data={"source_character_id": ids["source"], "units": "cm", "prim": "fringe"}),
                   422, "unknown_prim")
    assert_problem(client.post("/v1/hairstyles", headers=AUTH, files={"hair": ("groom.abc", groom)},
                               data={"source_character_id": ids["source"], "units": "cm", "guides_from": "sim"}),
                   422, "no_guide_flags")
    response = client.post("/v1/hairstyles", headers=AUTH, files={"hair": ("groom.abc", groom)},
                           data={"source_character_id": ids["source"], "units": "cm", "guides_from": "groom_guide",
                                 "prim": "curves"})
    assert response.status_code == 201, response.text
    assert response.json()["prim"] == "curves" and response.json()["format"] == "abc"
    assert response.json()["options"]["guides_from"] == "groom_guide"
    response = client.post("/v1/retargets", headers=AUTH, json={
        "hairstyle_id": response.json()["id"], "target_character_ids": [ids["target"]],
        "options": {"max_iterations": 10}, "output_format": "abc", "flag_guides": True})
    assert response.status_code == 202, response.text
    job = response.json()["jobs"][0]["id"]
    done = wait_for(client, f"/v1/jobs/{job}", lambda b: b["state"] in ("succeeded", "failed", "cancelled"))
    assert done["state"] == "succeeded", done
    assert done["metrics"]["penetrating_particles"] == 0
    result = client.get(f"/v1/jobs/{job}/result", headers=AUTH)
    assert result.status_code == 200 and result.content[:5] == b"Ogawa"
    back = read_hair_bytes(result.content, "abc")
    np.testing.assert_array_equal(back.attributes["groom_group_id"].values, groups)
    np.testing.assert_array_equal(back.attributes["groom_guide"].values, flags)  # the solve's guides: the flagged
    assert np.abs(back.points - hair.points @ Y_UP_TO_Z_UP / 0.01).max() > 0.1  # moved, in cm
    usda = client.get(f"/v1/jobs/{job}/result", headers=AUTH, params={"format": "usda"})
    assert usda.status_code == 200 and usda.headers["content-type"].startswith("model/vnd.usda")
    (tmp_path / "result.usda").write_bytes(usda.content)
    stage = Usd.Stage.Open(str(tmp_path / "result.usda"))
    assert UsdGeom.GetStageUpAxis(stage) == "Z" and UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01)
    converted = read_hair_bytes(usda.content, "usda", units="cm")
    np.testing.assert_allclose(converted.points, back.points * 0.01, atol=1e-8)
    np.testing.assert_array_equal(converted.attributes["groom_group_id"].values, groups)
