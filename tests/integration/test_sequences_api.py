"""Sequence jobs end to end (``sequence`` in ``/v1/retargets`` and ``/v1/batches``): the tests' Redis, a real
worker process, the FastAPI app in-process. An animated USD stage (centimetres, Z up, time codes from 1001) and
three OBJ characters of one sweep: one job each, per-frame progress, one animated result read back with its time
samples, any frame downloadable in any format, the dashboard's frames; and the requests refused before any job."""

from __future__ import annotations

import io
import json
import re
import zipfile

import numpy as np
import pytest

from hairport.solver import display as wire
from hairport.solver.io.character.obj import write_obj
from hairport.solver.io.hair import read_hair
from hairport.solver.synthetic import toy
from tests.solver.io.character.test_alembic import animated_archive
from tests.solver.io.character.test_frames import DRIFT_CM, animated_stage
from tests.solver.io.hair.test_registry import time_samples
from tests.solver.synthetic.toy_fixtures import PRESET_B

from .test_service_api import AUTH, assert_problem, files, service, upload_character, uploaded, wait_for  # noqa: F401

FRAMES = 3
ENDED = ("succeeded", "failed", "cancelled")


@pytest.fixture(scope="module")
def sweep(service, files, uploaded, tmp_path_factory):  # noqa: F811
    """The toy source swept in FRAMES steps to a larger toy: an animated stage and three OBJ characters, uploaded."""
    client = service["client"]
    d = tmp_path_factory.mktemp("sweep")
    source, other = toy.toy_character(name="source"), toy.toy_character(**PRESET_B)
    bodies = [source.vertices + t * (other.vertices - source.vertices) for t in np.linspace(0.0, 1.0, FRAMES)]
    animated_stage(d / "anim.usda", bodies, source.faces)
    animated_archive(d / "anim.abc", source.faces, bodies)
    archive = client.post("/v1/characters", headers=AUTH, files={"mesh": ("anim.abc", (d / "anim.abc").read_bytes())})
    assert archive.status_code == 201, archive.text
    stage = client.post("/v1/characters", headers=AUTH, files={"mesh": ("anim.usda", (d / "anim.usda").read_bytes())})
    assert stage.status_code == 201, stage.text
    meshes = []
    for number, vertices in enumerate(bodies):
        write_obj(d / f"frame{number}.obj", vertices, source.faces, f"sweep frame {number}")
        response = client.post("/v1/characters", headers=AUTH, data={"units": "m"},
                               files={"mesh": (f"frame{number}.obj", (d / f"frame{number}.obj").read_bytes())})
        assert response.status_code == 201, response.text
        meshes.append(response.json()["id"])
    return {"stage": stage.json()["id"], "archive": archive.json()["id"], "meshes": meshes, "bodies": bodies, "dir": d}


def run_job(client, request: dict) -> dict:
    response = client.post("/v1/retargets", headers=AUTH, json=request)
    assert response.status_code == 202, response.text
    (job,) = response.json()["jobs"]
    return wait_for(client, f"/v1/jobs/{job['id']}", lambda body: body["state"] in ENDED)


def test_an_animated_stage_is_one_job_with_one_animated_result(service, uploaded, sweep, tmp_path):  # noqa: F811
    client = service["client"]
    job = run_job(client, {"hairstyle_id": uploaded["hairstyle"], "target_character_ids": [sweep["stage"]],
                           "sequence": {"frames": "1001:1003"}, "options": {"max_iterations": 5}})
    assert job["state"] == "succeeded", job
    assert job["frames"] == FRAMES and job["frames_done"] == FRAMES and job["output_format"] == "usdc"
    assert job["options"]["spacing"] == 3.0  # a sequence's own default, shown in its options
    assert job["sequence"]["frames"] == "1001:1003" and job["sequence"]["frames_from"] == "animation"
    metrics = job["metrics"]
    assert metrics["frames"] == FRAMES and metrics["penetrating_particles_max"] == 0
    assert [frame["time"] for frame in metrics["frames_detail"]] == [1001.0, 1002.0, 1003.0]
    assert metrics["frames_that_pop"] == 0 and not any(frame.get("pops") for frame in metrics["frames_detail"])

    # the animated result: one time sample per frame, the stage moving 2 cm a frame along X carries the hair
    (tmp_path / "hair.usdc").write_bytes(client.get(f"/v1/jobs/{job['id']}/result", headers=AUTH).content)
    points, seconds = time_samples(tmp_path / "hair.usdc", "usdc")
    assert np.allclose(seconds * 30.0, [1001.0, 1002.0, 1003.0])  # the stage's 30 time codes a second
    drift = np.median(points[1][:, 0] - points[0][:, 0])  # the groom file's units (m)
    assert abs(drift - 0.01 * DRIFT_CM) < 5e-3, drift
    # the same frames in another animated format, and one frame in any format
    (tmp_path / "hair.usda").write_bytes(client.get(f"/v1/jobs/{job['id']}/result?format=usda", headers=AUTH).content)
    assert np.array_equal(time_samples(tmp_path / "hair.usda", "usda")[1], seconds)
    one = client.get(f"/v1/jobs/{job['id']}/result?format=ply&frame=1", headers=AUTH)
    assert one.status_code == 200 and f"{job['id']}.0001.ply" in one.headers["content-disposition"]
    (tmp_path / "frame1.ply").write_bytes(one.content)
    assert np.abs(read_hair(tmp_path / "frame1.ply").points - points[1]).max() < 1e-6
    assert_problem(client.get(f"/v1/jobs/{job['id']}/result?format=ply", headers=AUTH), 422, "bad_frames")
    assert_problem(client.get(f"/v1/jobs/{job['id']}/result?frame=3", headers=AUTH), 422, "bad_frames")

    # what the dashboard plays: each frame's strands and body
    drawn = [wire.decode(client.get(f"/v1/jobs/{job['id']}/display?frame={k}&strands=20", headers=AUTH).content)[1]
             for k in range(FRAMES)]
    assert np.median(drawn[2]["positions"][:, 0] - drawn[0]["positions"][:, 0]) > 0.01 * DRIFT_CM
    assert all(int(arrays["inside"].sum()) == 0 for arrays in drawn)
    bodies = [wire.decode(client.get(f"/v1/jobs/{job['id']}/body?frame={k}", headers=AUTH).content)[1]["vertices"]
              for k in (0, 2)]
    assert np.abs(bodies[1] - bodies[0]).max() > 0.02
    assert_problem(client.get(f"/v1/jobs/{job['id']}/display?frame=5", headers=AUTH), 422, "bad_frames")
    assert_problem(client.get(f"/v1/jobs/{job['id']}/display?layer=source&frame=1", headers=AUTH), 422, "bad_frames")
    report = client.get(f"/v1/jobs/{job['id']}/report", headers=AUTH).json()
    assert [frame["time"] for frame in report["frames"]] == [1001.0, 1002.0, 1003.0]
    assert report["frames"][2]["metrics"]["coherence"]["largest_jump_m"] <= \
        report["frames"][2]["metrics"]["coherence"]["jump_bound_m"]


def test_an_alembic_animated_mesh_uploaded_as_a_character_is_a_sequence(service, uploaded, sweep):  # noqa: F811
    client = service["client"]
    record = client.get(f"/v1/characters/{sweep['archive']}", headers=AUTH).json()
    assert record["vertices"] == len(sweep["bodies"][0])  # the upload reads its first sample
    job = run_job(client, {"hairstyle_id": uploaded["hairstyle"], "target_character_ids": [sweep["archive"]],
                           "sequence": {"frames": "0:2"}, "output_format": "usda", "options": {"max_iterations": 5}})
    assert job["state"] == "succeeded" and job["frames"] == FRAMES, job
    assert job["metrics"]["penetrating_particles_max"] == 0
    assert [frame["time"] for frame in job["metrics"]["frames_detail"]] == [0.0, 1.0, 2.0]


def test_a_skeleton_animation_uploaded_as_a_character_is_a_sequence(service, uploaded, sweep):  # noqa: F811
    """A skinned stage posed by a UsdSkel.Animation (a blend shape toward the larger toy, the root drifting 2 cm a
    frame): the upload reads its bind pose, the job each time code's pose."""
    from tests.solver.io.character.usd_samples import add_skel_animation, write_scene

    client = service["client"]
    source, other = toy.toy_character(name="source"), toy.toy_character(**PRESET_B)
    path = sweep["dir"] / "skel.usda"
    write_scene(path, source)
    add_skel_animation(path, source, other, [1001.0, 1002.0, 1003.0], DRIFT_CM)
    response = client.post("/v1/characters", headers=AUTH, files={"mesh": ("skel.usda", path.read_bytes())})
    assert response.status_code == 201 and response.json()["has_skeleton"], response.text
    job = run_job(client, {"hairstyle_id": uploaded["hairstyle"], "target_character_ids": [response.json()["id"]],
                           "sequence": {"frames": "1001:1003"}, "options": {"max_iterations": 5}})
    assert job["state"] == "succeeded" and job["frames"] == FRAMES, job
    assert job["metrics"]["penetrating_particles_max"] == 0 and job["metrics"]["frames_that_pop"] == 0
    bodies = [wire.decode(client.get(f"/v1/jobs/{job['id']}/body?frame={k}", headers=AUTH).content)[1]["vertices"]
              for k in (0, 2)]
    assert np.abs(bodies[1] - bodies[0]).max() > 0.02  # posed: the body at frame 1003 is the larger toy


def test_characters_in_order_are_the_frames_of_one_job(service, uploaded, sweep, tmp_path):  # noqa: F811
    client = service["client"]
    job = run_job(client, {"hairstyle_id": uploaded["hairstyle"], "target_character_ids": sweep["meshes"],
                           "sequence": {"frames_from": "characters", "frames": "0:2:2", "temporal": 1e4},
                           "output_format": "abc", "options": {"max_iterations": 5, "spacing": 0}})
    assert job["state"] == "succeeded", job
    assert job["options"]["spacing"] == 0.0  # named in the request: kept
    assert job["target_character_id"] == sweep["meshes"][0] and job["frames"] == 2
    assert job["sequence"]["character_ids"] == [sweep["meshes"][0], sweep["meshes"][2]]
    assert job["metrics"]["penetrating_particles_max"] == 0
    (tmp_path / "hair.abc").write_bytes(client.get(f"/v1/jobs/{job['id']}/result", headers=AUTH).content)
    points, seconds = time_samples(tmp_path / "hair.abc", "abc")
    assert np.allclose(seconds * 24.0, [0.0, 2.0]) and np.abs(points[1] - points[0]).max() > 1e-3  # frames 0 and 2
    # a job onto one body has no frames
    still = run_job(client, {"hairstyle_id": uploaded["hairstyle"], "target_character_ids": [sweep["meshes"][1]],
                             "options": {"max_iterations": 3}})
    assert still["state"] == "succeeded" and still["frames"] is None and still["output_format"] == "data"
    assert_problem(client.get(f"/v1/jobs/{still['id']}/result?frame=0", headers=AUTH), 422, "bad_frames")
    assert_problem(client.get(f"/v1/jobs/{still['id']}/display?frame=0", headers=AUTH), 422, "bad_frames")


@pytest.mark.parametrize("sequence, extra, code", [
    ({}, {}, "bad_frames"),  # an animation's frames are a range
    ({"frames": "3:1"}, {}, "bad_frames"),
    ({"frames": "1001:1003"}, {"output_format": "ply"}, "bad_option"),
    ({"frames": "1001:1003", "temporal": 1e4}, {"options": {"method": "naive"}}, "bad_option"),
    ({"frames": "1001:1003", "temporal": 1e4, "warm_start": False}, {}, "bad_option"),
    ({"morph_weights": [[0.0, 1.0], [0.5]]}, {}, "bad_frames"),
    ({"frames": "1001:1003"}, {"landmarks": {"source": {"a": [0, 0, 0]}, "target": {"a": [0, 0, 0]}}},
     "bad_landmarks"),
    ({"frames": "1001:1003", "temporal": -1}, {}, "bad_option"),
    ({"frames": "1001:1003", "frames_from": "files"}, {}, "invalid_request"),
])
def test_sequences_that_cannot_run_are_refused_before_any_job(service, uploaded, sweep, sequence, extra,  # noqa: F811
                                                              code):
    client = service["client"]
    before = client.get("/v1/jobs?limit=1", headers=AUTH).json()["total"]
    response = client.post("/v1/retargets", headers=AUTH, json={
        "hairstyle_id": uploaded["hairstyle"], "target_character_ids": [sweep["stage"]], "sequence": sequence,
        **extra})
    assert_problem(response, 422, code)
    assert client.get("/v1/jobs?limit=1", headers=AUTH).json()["total"] == before


def test_frames_of_characters_past_the_list_or_in_a_batch_are_refused(service, uploaded, sweep,  # noqa: F811
                                                                      monkeypatch):
    from hairport.solver.io.character import frames

    client = service["client"]
    # more vertices in all than a sequence may hold (every frame's mesh is held at once): 413 before any job
    monkeypatch.setattr(frames, "MAX_SEQUENCE_VERTICES", 2 * len(sweep["bodies"][0]))
    assert_problem(client.post("/v1/retargets", headers=AUTH, json={
        "hairstyle_id": uploaded["hairstyle"], "target_character_ids": sweep["meshes"],
        "sequence": {"frames_from": "characters"}}), 413, "too_large")
    monkeypatch.undo()
    characters = {"frames_from": "characters", "frames": "0:5"}
    assert_problem(client.post("/v1/retargets", headers=AUTH, json={
        "hairstyle_id": uploaded["hairstyle"], "target_character_ids": sweep["meshes"], "sequence": characters}),
        422, "bad_frames")
    assert_problem(client.post("/v1/batches", headers=AUTH, json={
        "hairstyle_ids": [uploaded["hairstyle"]], "target_character_ids": sweep["meshes"],
        "sequence": {"frames_from": "characters"}}), 422, "bad_frames")


@pytest.mark.parametrize("target, frames, code", [("stage", "1001:1009", "bad_frames"),
                                                  ("mesh", "0:2", "not_animated")])
def test_frames_the_target_does_not_have_fail_the_job(service, uploaded, sweep, target, frames, code):  # noqa: F811
    client = service["client"]
    character = sweep["stage"] if target == "stage" else sweep["meshes"][0]
    job = run_job(client, {"hairstyle_id": uploaded["hairstyle"], "target_character_ids": [character],
                           "sequence": {"frames": frames}})
    assert job["state"] == "failed" and job["error"]["code"] == code, job
    assert_problem(client.get(f"/v1/jobs/{job['id']}/result", headers=AUTH), 409, "job_not_succeeded")


def test_a_batch_of_animated_targets_zips_one_animated_result_per_pair(service, uploaded, sweep, tmp_path):  # noqa: F811
    client = service["client"]
    response = client.post("/v1/batches", headers=AUTH, json={
        "hairstyle_ids": [uploaded["hairstyle"]], "target_character_ids": [sweep["stage"]],
        "sequence": {"frames": "1001:1002"}, "options": {"max_iterations": 3}})
    assert response.status_code == 202, response.text
    batch = wait_for(client, response.json()["links"]["self"], lambda body: body["state"] == "done")
    assert batch["counts"]["succeeded"] == 1 and batch["output_format"] == "usdc"
    archive = zipfile.ZipFile(io.BytesIO(client.get(batch["links"]["results"], headers=AUTH).content))
    (pair,) = json.loads(archive.read("manifest.json"))["pairs"]
    (tmp_path / "pair.usdc").write_bytes(archive.read(pair["files"]["result"]))
    assert np.allclose(time_samples(tmp_path / "pair.usdc", "usdc")[1] * 30.0, [1001.0, 1002.0])


def test_a_running_sequence_shows_its_frames_and_stops_when_cancelled(service, uploaded, sweep):  # noqa: F811
    """Slow frames (every iteration, no early stop): the job's frame counts and stage move while it runs; a cancel
    stops it at the solver's next iteration and keeps no output."""
    client = service["client"]
    slow = {"method": "global", "max_iterations": 60, "step_tolerance": 0, "energy_tolerance": 0}
    response = client.post("/v1/retargets", headers=AUTH, json={
        "hairstyle_id": uploaded["hairstyle"], "target_character_ids": sweep["meshes"] * 4, "options": slow,
        "sequence": {"frames_from": "characters"}})
    assert response.status_code == 202, response.text
    path = f"/v1/jobs/{response.json()['jobs'][0]['id']}"
    running = wait_for(client, path, lambda body: body["frames_done"] >= 1 or body["state"] in ENDED)
    assert running["state"] == "running" and running["frames"] == 4 * FRAMES, running
    assert re.match(r"frame \d+: ", running["stage"]), running["stage"]  # the frame being solved
    assert 0 < running["progress"] < 1
    cancelled = client.delete(path, headers=AUTH)
    assert cancelled.status_code == 200 and cancelled.json()["cancel_requested"]
    done = wait_for(client, path, lambda body: body["state"] in ENDED)
    assert done["state"] == "cancelled" and done["frames_done"] < 4 * FRAMES, done
    assert_problem(client.get(f"{path}/result", headers=AUTH), 409, "job_not_succeeded")
