"""``/v1/jobs``: listing from the index, one job, outputs of unfinished jobs, cancelling a queued job."""

import numpy as np

from hairport import solver
from hairport.records import BlobRef, JobRecord, PreprocessSettings, now
from hairport.service.auth import owner_of

from ..conftest import AUTH, KEY


def add_jobs(client, count: int) -> list[str]:
    repository = client.app.state.repository
    ids = []
    for number in range(count):
        job = JobRecord(id=f"{number + 1:032x}", owner=owner_of(KEY), hairstyle_id="h" * 32,
                        target_character_id="c" * 32, options={}, preprocess_options=PreprocessSettings(k=5, guides=9),
                        artifact_key="a" * 64, output_format="ply", created_at=now() + number, updated_at=now(),
                        task_id=f"task-{number}")
        repository.create_job(job)
        ids.append(job.id)
    return ids


def test_listing_pages_and_filters(client):
    ids = add_jobs(client, 5)
    client.app.state.repository.set_job(ids[0], state="failed")
    page = client.get("/v1/jobs", headers=AUTH, params={"limit": 2}).json()
    assert [job["id"] for job in page["jobs"]] == [ids[4], ids[3]] and page["total"] == 5 and page["next_offset"] == 2
    last = client.get("/v1/jobs", headers=AUTH, params={"limit": 2, "offset": 4}).json()
    assert [job["id"] for job in last["jobs"]] == [ids[0]] and last["next_offset"] is None
    failed = client.get("/v1/jobs", headers=AUTH, params={"state": "failed"}).json()
    assert failed["total"] == 1 and failed["jobs"][0]["links"] == {"self": f"/v1/jobs/{ids[0]}"}
    assert client.get("/v1/jobs", headers=AUTH, params={"state": "paused"}).status_code == 422


def test_outputs_of_an_unfinished_job_are_409(client):
    job_id = add_jobs(client, 1)[0]
    assert client.get(f"/v1/jobs/{job_id}", headers=AUTH).json()["state"] == "queued"
    for tail in ("result", "preview.png", "report"):
        response = client.get(f"/v1/jobs/{job_id}/{tail}", headers=AUTH)
        assert response.status_code == 409 and response.json()["code"] == "job_not_succeeded"


def test_cancelling_a_queued_job(client):
    job_id = add_jobs(client, 1)[0]
    cancelled = client.delete(f"/v1/jobs/{job_id}", headers=AUTH).json()
    assert cancelled["state"] == "cancelled" and cancelled["stage"] == "cancelled" and cancelled["finished_at"]
    again = client.delete(f"/v1/jobs/{job_id}", headers=AUTH).json()
    assert again == cancelled
    assert client.get("/v1/jobs", headers=AUTH, params={"state": "cancelled"}).json()["total"] == 1


def test_results_in_any_format_and_gone_outputs(client, tmp_path):
    repository = client.app.state.repository
    job_id = add_jobs(client, 1)[0]
    hair = solver.Hair.from_strands([np.array([[0, 0, 0], [0, 0.01, 0], [0, 0.02, 0.0]]),
                                     np.array([[0.01, 0, 0], [0.01, 0.01, 0.0]])])
    solver.write_hair(tmp_path / "r.npz", hair, format="npz")
    blob = repository.storage.save_file(tmp_path / "r.npz", ".npz")
    gone = BlobRef(sha256="f" * 64, suffix=".png")
    repository.set_job(job_id, state="succeeded", outputs={"npz": BlobRef(sha256=blob.sha256, suffix=".npz"),
                                                           "preview": gone, "report": gone})
    stored = client.get(f"/v1/jobs/{job_id}/result", headers=AUTH, params={"format": "npz"})
    assert stored.status_code == 200 and stored.content == (tmp_path / "r.npz").read_bytes()
    converted = client.get(f"/v1/jobs/{job_id}/result", headers=AUTH, params={"format": "obj"})
    assert converted.status_code == 200 and converted.headers["content-type"] == "model/obj"
    np.testing.assert_allclose(solver.read_hair(write(tmp_path / "c.obj", converted.content)).points, hair.points,
                               atol=1e-7)
    assert list((repository.storage.root / "work").iterdir()) == []  # the scratch folder went with the response
    missing = client.get(f"/v1/jobs/{job_id}/preview.png", headers=AUTH)
    assert (missing.status_code, missing.json()["code"]) == (410, "gone")
    links = client.get(f"/v1/jobs/{job_id}", headers=AUTH).json()["links"]
    assert sorted(links) == ["preview", "report", "result", "self"]


def write(path, content: bytes):
    path.write_bytes(content)
    return path


def test_a_result_in_millimetres_converts_in_millimetres(client, tmp_path):
    """Results are stored in the groom's units (the .npz records them); a conversion keeps them."""
    repository = client.app.state.repository
    job_id = add_jobs(client, 1)[0]
    hair = solver.Hair.from_strands([np.array([[0.0, 1.6, 0.0], [0.0, 1.61, 0.01], [0.0, 1.62, 0.03]])])
    solver.write_hair(tmp_path / "r.npz", hair, units="mm")
    blob = repository.storage.save_file(tmp_path / "r.npz", ".npz")
    repository.set_job(job_id, state="succeeded", outputs={"npz": BlobRef(sha256=blob.sha256, suffix=".npz")})
    converted = client.get(f"/v1/jobs/{job_id}/result", headers=AUTH, params={"format": "obj"})
    assert converted.status_code == 200, converted.text
    in_file = solver.read_hair(write(tmp_path / "c.obj", converted.content)).points  # the file's own numbers
    np.testing.assert_allclose(in_file, hair.points * 1000.0, atol=1e-4)
