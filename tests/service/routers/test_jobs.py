"""``/v1/jobs``: listing from the index, one job, outputs of unfinished jobs, cancelling a queued job."""

import json

import numpy as np
import pytest

from hairport import solver
from hairport.records import BlobRef, JobRecord, PreprocessSettings, now
from hairport.service.auth import owner_of
from hairport.solver import display
from hairport.solver import display as solver_display
from hairport.solver.model.frame import InputFrame

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


def test_a_cancel_with_the_broker_down_is_whole_and_its_unrevoked_message_logged(client, client_without_broker,
                                                                                 caplog):
    """Revoking is best effort (a worker reads the cancel from the record before it starts a job): with the
    broker down the cancel applies all the same, and the message left in the queue is logged."""
    queued, running = add_jobs(client, 2)
    client.app.state.repository.set_job(running, state="running")
    with caplog.at_level("WARNING", logger="hairport.worker.queue"):
        cancelled = client_without_broker.delete(f"/v1/jobs/{queued}", headers=AUTH)
        stopping = client_without_broker.delete(f"/v1/jobs/{running}", headers=AUTH)
    assert cancelled.status_code == 200 and cancelled.json()["state"] == "cancelled"
    assert stopping.status_code == 200 and stopping.json()["state"] == "running" and stopping.json()["cancel_requested"]
    records = [client.app.state.repository.job(job_id) for job_id in (queued, running)]
    assert [(job.state, job.cancel_requested) for job in records] == [("cancelled", True), ("running", True)]
    unrevoked = [record.getMessage() for record in caplog.records if "not revoked" in record.getMessage()]
    assert len(unrevoked) == 1 and "task-0" in unrevoked[0]  # the queued job's; a running one has none waiting


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


#: the frame of a groom file with Z up (its rotation takes a drawn curve to the file's axes)
Z_UP = InputFrame(units="cm", up="+z", front="-y")


def succeeded_with_scene(client, tmp_path, hairline_error=None, with_artifact=True, wrapped=None) -> str:
    """A succeeded job whose outputs hold a scene (a 3-strand result, 2 particles inside, a hairline, and the
    ``wrapped`` body (vertices, faces) when given) and whose artifact is a real preprocessed groom on an icosphere
    head."""
    from hairport.records import ArtifactRecord
    from hairport.solver import pipeline
    from tests.solver.hair_shapes import outward_strands, sphere_character

    repository = client.app.state.repository
    job_id = add_jobs(client, 1)[0]
    head = sphere_character()
    groom = outward_strands(head, n_strands=12, n_points=6)
    result = groom.with_points(groom.points + 0.001)
    inside = np.zeros(groom.n_particles, bool)
    inside[[3, 7]] = True
    hairline = {"points": [[0.05, 0.0, 0.0], [0.0, 0.02, 0.05], [-0.05, 0.0, 0.0]], "turning_points": [0, 2]}
    scene = display.scene_arrays(result.points, result.offsets, inside, None, head.vertices, head.faces,
                                Z_UP.rotation, hairline if hairline_error is None else
                                {"points": [], "turning_points": []}, {} if hairline_error else {"round": hairline},
                                wrapped)
    scene["meta"] = np.frombuffer(json.dumps({"groom_units": "cm", "hairline_error": hairline_error}).encode(), np.uint8)
    display.save_scene(tmp_path / "scene.npz", scene)
    blob = repository.storage.save_file(tmp_path / "scene.npz", ".npz")
    repository.set_job(job_id, state="succeeded", outputs={"scene": BlobRef(sha256=blob.sha256, suffix=".npz")})
    if with_artifact:
        solver.save_adaptable(pipeline.preprocess(head, groom), tmp_path / "groom.hpa")
        saved = repository.storage.save_file(tmp_path / "groom.hpa", ".hpa")
        repository.put(ArtifactRecord(key="a" * 64, sha256=saved.sha256, size=saved.size, format_version=3,
                                      seconds=0.1, guides=9, created_at=now()), "a" * 64)
    return job_id


def test_a_job_draws_its_result_decimated_with_the_particles_inside_flagged(client, tmp_path):
    job_id = succeeded_with_scene(client, tmp_path)
    response = client.get(f"/v1/jobs/{job_id}/display", headers=AUTH)
    assert response.status_code == 200 and response.headers["content-type"] == display.MEDIA_TYPE
    header, arrays = solver_display.decode(response.content)
    assert header["drawn_strands"] == 12 and header["drawn_vertices"] == 72 and header["inside"] == 2
    assert arrays["positions"].shape == (72, 3) and arrays["inside"].sum() == 2
    strided = solver_display.decode(client.get(f"/v1/jobs/{job_id}/display", headers=AUTH,
                                               params={"strands": 4, "stride": 2}).content)
    assert strided[0]["drawn_strands"] == 4 and strided[0]["drawn_vertices"] == 4 * 4
    source = solver_display.decode(client.get(f"/v1/jobs/{job_id}/display", headers=AUTH,
                                              params={"layer": "source"}).content)
    assert source[0]["inside"] is None and source[0]["drawn_vertices"] == 72
    assert np.abs(source[1]["positions"] - arrays["positions"]).max() == pytest.approx(0.001, abs=1e-6)
    for params, status in (({"stride": 0}, 422), ({"max_vertices": display.MAX_DISPLAY_VERTICES + 1}, 422),
                           ({"layer": "initial"}, 422), ({"strands": 0}, 422)):
        assert client.get(f"/v1/jobs/{job_id}/display", headers=AUTH, params=params).status_code == status


def test_a_job_draws_its_bodies_and_hands_out_its_hairlines(client, tmp_path):
    job_id = succeeded_with_scene(client, tmp_path)
    target = solver_display.decode(client.get(f"/v1/jobs/{job_id}/body", headers=AUTH).content)
    source = solver_display.decode(client.get(f"/v1/jobs/{job_id}/body", headers=AUTH,
                                              params={"layer": "source"}).content)
    assert target[0]["up"] == [0.0, 1.0, 0.0] and target[1]["faces"].dtype == np.uint32
    np.testing.assert_array_equal(target[1]["faces"], source[1]["faces"])
    hairline = client.get(f"/v1/jobs/{job_id}/hairline", headers=AUTH).json()
    assert hairline["points"][1] == [0.0, 0.02, 0.05] and hairline["turning_points"] == [0, 2]
    assert set(hairline["presets"]) == {"round"} and hairline["groom_units"] == "cm"
    assert hairline["groom_rotation"] == Z_UP.rotation.tolist()


def test_a_wrapped_job_draws_its_wrapped_body_and_another_answers_no_wrap(client, tmp_path):
    import trimesh

    # the source's mesh in another shape: a coarser icosphere than the 642-vertex target head
    coarse = trimesh.creation.icosphere(2, radius=0.09)
    wrapped = succeeded_with_scene(client, tmp_path, wrapped=(np.asarray(coarse.vertices), coarse.faces))
    response = client.get(f"/v1/jobs/{wrapped}/body", headers=AUTH, params={"layer": "wrapped"})
    assert response.status_code == 200 and response.headers["content-type"] == display.MEDIA_TYPE
    header, arrays = solver_display.decode(response.content)
    assert (header["layer"], header["vertices"], header["faces"]) == ("wrapped", 162, 320)
    np.testing.assert_allclose(arrays["vertices"], coarse.vertices, atol=1e-6)
    np.testing.assert_array_equal(arrays["faces"], coarse.faces)
    target = solver_display.decode(client.get(f"/v1/jobs/{wrapped}/body", headers=AUTH).content)[0]
    assert (target["layer"], target["vertices"]) == ("target", 642)
    unwrapped = succeeded_with_scene(client, tmp_path, with_artifact=False)  # its scene has no wrapped body
    response = client.get(f"/v1/jobs/{unwrapped}/body", headers=AUTH, params={"layer": "wrapped"})
    assert response.status_code == 409 and response.headers["content-type"] == "application/problem+json"
    assert response.json()["code"] == "no_wrap" and "not wrapped" in response.json()["detail"]
    assert client.get(f"/v1/jobs/{unwrapped}/body", headers=AUTH, params={"layer": "wrap"}).status_code == 422


def test_display_answers_name_what_is_missing(client, tmp_path):
    queued = add_jobs(client, 1)[0]
    for tail in ("display", "body", "hairline"):
        response = client.get(f"/v1/jobs/{queued}/{tail}", headers=AUTH)
        assert response.status_code == 409 and response.json()["code"] == "job_not_succeeded"
    older = add_jobs(client, 1)[0]  # a job that ran before scenes were saved
    client.app.state.repository.set_job(older, state="succeeded", outputs={})
    response = client.get(f"/v1/jobs/{older}/display", headers=AUTH)
    assert response.status_code == 409 and response.json()["code"] == "no_scene"
    bald = succeeded_with_scene(client, tmp_path, hairline_error="no front hairline: the roots cover the whole head",
                                with_artifact=False)
    response = client.get(f"/v1/jobs/{bald}/hairline", headers=AUTH)
    assert response.status_code == 409 and response.json()["code"] == "no_hairline"
    assert "cover the whole head" in response.json()["detail"]
    response = client.get(f"/v1/jobs/{bald}/display", headers=AUTH, params={"layer": "source"})
    assert response.status_code == 410 and response.json()["code"] == "gone"
    other = client.get(f"/v1/jobs/{bald}/display", headers={"X-API-Key": "someone-else"})
    assert other.status_code == 401
