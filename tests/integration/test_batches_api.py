"""Batches end to end (``/v1/batches``): the tests' Redis, a real worker process, the FastAPI app in-process.
Three grooms x four toy characters: twelve results, a manifest, counts by state while the batch runs, and a
cancelled batch whose remaining jobs never run."""

from __future__ import annotations

import io
import json
import time
import zipfile

import numpy as np
import pytest

from .test_service_api import AUTH, files, service, upload_character, wait_for  # noqa: F401 - fixtures

DONE = ("succeeded", "failed", "cancelled")


@pytest.fixture(scope="module")
def grid(service, files, tmp_path_factory):  # noqa: F811
    from hairport.solver.io.hair import write_hair
    from hairport.solver.synthetic import toy
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import write_character

    client = service["client"]
    folder = tmp_path_factory.mktemp("grid")
    wide = toy.toy_character(head_scale=(1.05, 1.0, 1.1), shoulder_width=0.45, name="wide")
    write_character(wide, folder / "wide.obj", folder / "wide.skeleton.json")
    targets = [upload_character(client, files, name).json()["id"] for name in ("source", "target", "tall")]
    targets.append(upload_character(client, {"dir": folder}, "wide").json()["id"])
    source = toy.toy_character(name="source")
    hairstyles = []
    for seed in (0, 1, 2):
        write_hair(folder / f"groom{seed}.data", generate_groom(source, "short", 40, 10, seed=seed))
        response = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": targets[0], "guides": "10"},
                               files={"hair": (f"groom{seed}.data", (folder / f"groom{seed}.data").read_bytes())})
        assert response.status_code == 201, response.text
        hairstyles.append(response.json()["id"])
    return {"hairstyles": hairstyles, "targets": targets}


def test_a_3_by_4_batch_gives_12_results_and_a_manifest(service, grid, tmp_path):  # noqa: F811
    from hairport import solver

    client = service["client"]
    response = client.post("/v1/batches", headers=AUTH, json={
        "hairstyle_ids": grid["hairstyles"], "target_character_ids": grid["targets"],
        "options": {"max_iterations": 5}, "output_format": "ply"})
    assert response.status_code == 202, response.text
    batch = response.json()
    seen = []
    while (body := client.get(batch["links"]["self"], headers=AUTH).json())["state"] != "done":
        assert sum(body["counts"].values()) == 12 and body["counts"]["failed"] == 0, body["counts"]
        seen.append((body["counts"]["queued"], body["counts"]["running"], body["counts"]["succeeded"]))
        assert len(seen) < 2000, seen[-1]
        time.sleep(0.05)
    assert any(queued > 0 and succeeded > 0 for queued, _, succeeded in seen), seen  # counts moved while it ran
    assert body["counts"]["succeeded"] == 12 and body["progress"] == 1.0 and body["finished_at"] is not None

    archive = zipfile.ZipFile(io.BytesIO(client.get(body["links"]["results"], headers=AUTH).content))
    manifest = json.loads(archive.read("manifest.json"))
    assert len(manifest["pairs"]) == 12 and all(pair["state"] == "succeeded" for pair in manifest["pairs"])
    pairs = {(pair["hairstyle_id"], pair["target_character_id"]) for pair in manifest["pairs"]}
    assert pairs == {(h, t) for h in grid["hairstyles"] for t in grid["targets"]}
    for pair in manifest["pairs"]:
        assert pair["metrics"]["penetrating_particles"] == 0
        path = tmp_path / pair["files"]["result"].replace("/", "_")
        path.write_bytes(archive.read(pair["files"]["result"]))
        assert solver.read_hair(path).n_strands == 40
        assert json.loads(archive.read(pair["files"]["report"]))["metrics"]["penetrating_particles"] == 0


def test_cancelling_a_batch_stops_its_remaining_jobs(service, grid):  # noqa: F811
    client = service["client"]
    slow = {"method": "global", "max_iterations": 40, "step_tolerance": 0, "energy_tolerance": 0}
    batch = client.post("/v1/batches", headers=AUTH, json={
        "hairstyle_ids": grid["hairstyles"][:2], "target_character_ids": grid["targets"], "options": slow}).json()
    wait_for(client, batch["links"]["self"], lambda body: body["counts"]["running"] >= 1)
    cancelled = client.delete(batch["links"]["self"], headers=AUTH)
    assert cancelled.status_code == 200 and cancelled.json()["counts"]["cancelled"] >= 6, cancelled.json()
    done = wait_for(client, batch["links"]["self"], lambda body: body["state"] == "done")
    counts = done["counts"]
    assert counts["failed"] == 0 and counts["succeeded"] + counts["cancelled"] == 8 and counts["succeeded"] <= 1
    started = [job for job in done["jobs"]
               if client.get(job["links"]["self"], headers=AUTH).json()["started_at"] is not None]
    assert len(started) <= 2, started  # the running job, and at most one the worker had already taken
    assert np.isclose(done["progress"], 1.0)
