"""The job bodies, called as plain functions on a real storage with toy characters (no Celery)."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from hairport import solver
from hairport.records import (
    BlobRef,
    CharacterRecord,
    ErrorInfo,
    HairstyleRecord,
    JobRecord,
    PreprocessSettings,
    artifact_key,
    now,
)
from hairport.repository import Repository
from hairport.settings import Settings
from hairport.solver.io.character import load_character
from hairport.solver.io.character.obj import write_obj
from hairport.solver.synthetic import toy
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import write_character
from hairport.storage import LocalStorage
from hairport.worker import runner, runs

OWNER = "kowner"


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """A storage holding two toy characters, another topology, and a 30-strand groom (preprocessed once)."""
    root = tmp_path_factory.mktemp("runner")
    repository = Repository(LocalStorage(root / "storage", durable=False))
    settings = Settings(storage_dir=root / "storage")
    source = toy.toy_character(name="source")
    target = toy.toy_character(head_scale=(1.1, 0.95, 1.05), neck_length=0.15, shoulder_width=0.42, name="target")
    other = toy.toy_character(name="other")
    other = solver.Character(other.vertices, other.faces[:-1], other.skeleton, other.weights, "other")
    ids = {}
    for name, character in (("source", source), ("target", target), ("other", other)):
        mesh, skeleton = root / f"{name}.obj", root / f"{name}.skeleton.json"
        write_character(character, mesh, skeleton)
        record = CharacterRecord(
            id=f"{len(ids) + 1:032x}", owner=OWNER, created_at=now(), vertices=character.n_vertices,
            faces=character.n_faces, bones=list(character.skeleton.names),
            mesh=BlobRef(sha256=repository.storage.save_file(mesh, ".obj").sha256, suffix=".obj"),
            skeleton=BlobRef(sha256=repository.storage.save_file(skeleton, ".json").sha256, suffix=".json"),
        )
        repository.put(record, record.id)
        ids[name] = record
    hair = generate_groom(source, "short", 30, 8, seed=1)
    ids["hairstyle"] = add_hairstyle(repository, ids["source"], hair, root / "groom.data", "a")
    runner.run_preprocess(repository, settings, ids["hairstyle"].id)
    return {"repository": repository, "settings": settings, "ids": ids, "root": root, "hair": hair}


def add_hairstyle(repository, character, hair, path, letter) -> HairstyleRecord:
    solver.write_hair(path, hair)
    blob = repository.storage.save_file(path, path.suffix)
    options = PreprocessSettings(k=5, guides=10)
    record = HairstyleRecord(
        id=letter * 32, owner=OWNER, created_at=now(), source_character_id=character.id,
        hair=BlobRef(sha256=blob.sha256, suffix=path.suffix), format=path.suffix[1:], units="m", options=options,
        artifact_key=artifact_key(character, blob.sha256, "m", options, solver.ARTIFACT_FORMAT_VERSION),
        strands=hair.n_strands, particles=hair.n_particles,
    )
    repository.put(record, record.id)
    return record


def add_job(world, target="target", hairstyle="hairstyle", options=None, **fields) -> JobRecord:
    repository, ids = world["repository"], world["ids"]
    style = ids[hairstyle]
    job = JobRecord(id=f"{np.random.default_rng().integers(1 << 62):032x}", owner=OWNER, hairstyle_id=style.id,
                    target_character_id=ids[target].id, options={"max_iterations": 5, **(options or {})},
                    preprocess_options=style.options, artifact_key=style.artifact_key, created_at=now(),
                    updated_at=now(), **{"output_format": "ply", **fields})
    repository.create_job(job)
    return job


def test_preprocessing_stores_the_artifact_once(world):
    repository, style = world["repository"], world["ids"]["hairstyle"]
    artifact = repository.artifact(style.artifact_key)
    assert artifact is not None and artifact.guides == 10 and artifact.format_version == solver.ARTIFACT_FORMAT_VERSION
    assert repository.preprocessing_status(style).state == "ready"
    before = sorted(repository.storage.root.rglob("*.hpa"))
    runner.run_preprocess(repository, world["settings"], style.id)
    assert sorted(repository.storage.root.rglob("*.hpa")) == before == [repository.storage.blob(artifact.sha256,
                                                                                                ".hpa").path]


def test_a_variant_is_preprocessed_under_its_own_key(world):
    repository, style = world["repository"], world["ids"]["hairstyle"]
    runner.run_preprocess(repository, world["settings"], style.id, {"k": 5, "guides": 4})
    key = repository.variant_key(style, PreprocessSettings(k=5, guides=4), solver.ARTIFACT_FORMAT_VERSION)
    assert key != style.artifact_key and repository.artifact(key).guides == 4


def test_bad_hair_fails_its_preprocessing_with_the_reason(world, tmp_path):
    repository = world["repository"]
    hair = world["hair"]
    points = hair.points.copy()
    points[3, 1] = np.nan
    path = tmp_path / "nan.npz"
    np.savez(path, format="hairport-hair", version=1, points=points, offsets=hair.offsets)
    style = add_hairstyle(repository, world["ids"]["source"], hair, tmp_path / "ok.npz", "b")
    blob = repository.storage.save_file(path, ".npz")
    style = style.model_copy(update={"hair": BlobRef(sha256=blob.sha256, suffix=".npz")})
    repository.put(style, style.id)
    runner.run_preprocess(repository, world["settings"], style.id)
    status = repository.preprocessing_status(style)
    assert status.state == "failed" and status.error.code == "non_finite"
    assert str(repository.storage.root) not in status.error.message


def test_a_retarget_stores_every_output_and_its_metrics(world):
    repository = world["repository"]
    job = add_job(world)
    runner.run_retarget(repository, world["settings"], job.id, "w1@host")
    done = repository.job(job.id)
    assert done.state == "succeeded" and done.attempts == 1 and done.worker == "w1@host", done.error
    assert done.progress == 1.0 and done.metrics["penetrating_particles"] == 0
    assert done.metrics["root_to_target_max"] < 1e-9 and done.timings["job"] >= done.timings["solve"] > 0
    assert sorted(done.outputs) == ["npz", "ply", "preview", "report", "scene"]
    ply = repository.storage.blob(done.outputs["ply"].sha256, ".ply")
    result = solver.read_hair(ply.path)
    assert (result.n_strands, result.n_particles) == (30, 240)
    report = json.loads(repository.storage.blob(done.outputs["report"].sha256, ".json").path.read_text())
    assert report["job"]["id"] == job.id and report["metrics"]["particles"] == 240
    png = repository.storage.blob(done.outputs["preview"].sha256, ".png").path.read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    assert list((repository.storage.root / "work").iterdir()) == []


def test_a_cancelled_job_does_not_run(world):
    repository = world["repository"]
    job = add_job(world, cancel_requested=True)
    runner.run_retarget(repository, world["settings"], job.id, "w1")
    assert repository.job(job.id).state == "cancelled" and repository.job(job.id).attempts == 0


def test_a_finished_job_is_not_run_again(world):
    repository = world["repository"]
    job = add_job(world, state="failed")
    runner.run_retarget(repository, world["settings"], job.id, "w1")
    assert repository.job(job.id).state == "failed" and repository.job(job.id).attempts == 0


def test_a_wrong_topology_with_the_wrap_off_fails_the_job_with_its_code(world):
    repository = world["repository"]
    job = add_job(world, target="other", options={"wrap": "off"})
    runner.run_retarget(repository, world["settings"], job.id, "w1")
    failed = repository.job(job.id)
    assert failed.state == "failed" and failed.error.code == "topology_mismatch" and failed.outputs is None
    assert "/blobs/" not in failed.error.message
    assert "options.wrap off keeps to the source's topology (wrap auto wraps" in failed.error.message


def test_a_body_that_traps_hair_fails_the_job_with_penetration_remaining(world, tmp_path):
    """The result would have particles inside the body: the job fails with the code, stores nothing."""
    from tests.solver.depth_cases import trap

    repository, settings = world["repository"], world["settings"]
    body, hair = trap(toy.toy_character(name="trap"))
    mesh, skeleton = tmp_path / "trap.obj", tmp_path / "trap.skeleton.json"
    write_character(body, mesh, skeleton)
    record = CharacterRecord(
        id="f" * 32, owner=OWNER, created_at=now(), vertices=body.n_vertices, faces=body.n_faces,
        bones=list(body.skeleton.names),
        mesh=BlobRef(sha256=repository.storage.save_file(mesh, ".obj").sha256, suffix=".obj"),
        skeleton=BlobRef(sha256=repository.storage.save_file(skeleton, ".json").sha256, suffix=".json"))
    repository.put(record, record.id)
    world["ids"]["trap"] = record
    world["ids"]["trapped"] = add_hairstyle(repository, record, hair, tmp_path / "trapped.data", "9")
    runner.run_preprocess(repository, settings, world["ids"]["trapped"].id)
    job = add_job(world, target="trap", hairstyle="trapped")
    runner.run_retarget(repository, settings, job.id, "w1")
    failed = repository.job(job.id)
    assert failed.state == "failed" and failed.error.code == "penetration_remaining" and failed.outputs is None
    assert "still inside after pushing them out" in failed.error.message and failed.metrics is None


def test_waiting_for_preprocessing(world):
    repository = world["repository"]
    job = add_job(world)
    pending = job.model_copy(update={"artifact_key": "e" * 64})
    repository.put(pending, job.id)
    repository.set_preprocessing("e" * 64, "running")
    with pytest.raises(runner.PreprocessingPending):
        runner.run_retarget(repository, world["settings"], job.id, "w1", polls=3)
    assert repository.job(job.id).stage == "waiting_for_preprocessing"
    runner.run_retarget(repository, world["settings"], job.id, "w1", polls=runner.PREPROCESS_POLL_LIMIT)
    assert repository.job(job.id).error.code == "preprocess_timeout"


def test_a_failed_preprocessing_fails_the_job(world):
    repository = world["repository"]
    job = add_job(world)
    repository.put(job.model_copy(update={"artifact_key": "d" * 64}), job.id)
    repository.set_preprocessing("d" * 64, "failed", error=ErrorInfo(code="truncated", message="the file is cut"))
    runner.run_retarget(repository, world["settings"], job.id, "w1")
    failed = repository.job(job.id)
    assert failed.state == "failed" and failed.error.code == "preprocess_failed"
    assert "the file is cut" in failed.error.message


def test_progress_is_written_at_most_every_interval(world, monkeypatch):
    repository = world["repository"]
    job = add_job(world)
    writes = []
    original = repository.set_job
    monkeypatch.setattr(repository, "set_job", lambda job_id, **fields: writes.append(fields) or original(job_id,
                                                                                                       **fields))
    progress = runner.JobProgress(repository, job.id)
    for step in range(100):
        progress("solve", step / 100, f"iteration {step}")
    progress("metrics", 0.95, "measuring")
    assert [w["stage"] for w in writes] == ["solve", "metrics"]
    assert repository.job(job.id).stage == "metrics" and repository.job(job.id).progress == 0.95
    assert progress.should_stop() is False
    repository.storage.update_record("jobs", job.id, lambda record: {**record, "cancel_requested": True})
    progress.last_check = -1e9
    assert progress.should_stop() is True


def test_inputs_in_centimetres_and_z_up_give_the_result_in_their_frame(world, tmp_path):
    """The same characters and groom as the world's, written Z up in cm and stating no units: the job's
    result is the world's result in that frame, and its metrics say what was inferred."""
    from hairport.solver.model.frame import InputFrame
    from tests.solver.frames import character_in

    repository, settings, root = world["repository"], world["settings"], world["root"]
    frame = InputFrame("cm", "z", "-y")
    records = {}
    for name, letter in (("source", "c"), ("target", "d")):
        character = load_character(root / f"{name}.obj")  # the numbers the world's files hold
        mesh, skeleton = tmp_path / f"{name}.obj", tmp_path / f"{name}.skeleton.json"
        write_character(character_in(frame, character), mesh, skeleton)
        document = json.loads(skeleton.read_text())
        del document["units"]
        skeleton.write_text(json.dumps(document))
        record = CharacterRecord(
            id=letter * 32, owner=OWNER, created_at=now(), vertices=character.n_vertices, faces=character.n_faces,
            bones=list(character.skeleton.names),
            mesh=BlobRef(sha256=repository.storage.save_file(mesh, ".obj").sha256, suffix=".obj"),
            skeleton=BlobRef(sha256=repository.storage.save_file(skeleton, ".json").sha256, suffix=".json"))
        repository.put(record, record.id)
        records[name] = record
    hair = solver.read_hair(root / "groom.data")
    path = tmp_path / "groom.npz"
    np.savez(path, format=np.array("hairport-hair"), version=np.array(1), points=frame.axes_out(hair.points) * 100,
             offsets=hair.offsets)
    blob = repository.storage.save_file(path, ".npz")
    options = PreprocessSettings(k=5, guides=10)
    style = HairstyleRecord(
        id="e" * 32, owner=OWNER, created_at=now(), source_character_id=records["source"].id,
        hair=BlobRef(sha256=blob.sha256, suffix=".npz"), format="npz", units="auto", options=options,
        artifact_key=artifact_key(records["source"], blob.sha256, "auto", options, solver.ARTIFACT_FORMAT_VERSION),
        strands=hair.n_strands, particles=hair.n_particles)
    repository.put(style, style.id)
    runner.run_preprocess(repository, settings, style.id)
    assert repository.preprocessing_status(style).state == "ready", repository.preprocessing_status(style).error
    world["ids"]["cm"], world["ids"]["cm-target"] = style, records["target"]
    framed, reference = add_job(world, target="cm-target", hairstyle="cm"), add_job(world)
    for job in (framed, reference):
        runner.run_retarget(repository, settings, job.id, "w1")
    framed, reference = repository.job(framed.id), repository.job(reference.id)
    assert framed.state == reference.state == "succeeded", framed.error
    stored = repository.storage.blob(framed.outputs["npz"].sha256, ".npz").path
    assert solver.recorded_hair_units(stored) == "cm"
    result = solver.read_hair(stored, units="cm")
    expected = solver.read_hair(repository.storage.blob(reference.outputs["npz"].sha256, ".npz").path)
    # the inputs agree to 1e-16 m (cm to m); five unconverged iterations carry that to ~1e-12 m
    assert np.abs(frame.axes_in(result.points) - expected.points).max() < 1e-9
    section = framed.metrics["input"]
    assert (section["units"]["hair"], section["axes"]["up"], section["axes"]["front"]) == ("cm", "+z", "-y")
    assert (section["target"]["units"], section["target"]["up"]) == ("cm", "+z") and section["warnings"] == []
    assert "input" not in reference.metrics or reference.metrics["input"]["units"]["hair"] == "m"


def test_characters_without_a_rig_are_anchored_by_their_surface(world, tmp_path):
    """Meshes without a skeleton (the common case of real heads): the hairstyle is preprocessed with
    anchoring auto, which takes the surface, and its job succeeds with every particle outside."""
    from tests.solver.synthetic.toy_fixtures import PRESET_B

    repository, settings = world["repository"], world["settings"]
    records = {}
    for name, letter, character in (("source", "f", toy.toy_character()), ("target", "g", toy.toy_character(**PRESET_B))):
        mesh = tmp_path / f"{name}.obj"
        write_obj(mesh, character.vertices, character.faces, "no rig")
        record = CharacterRecord(
            id=letter * 32, owner=OWNER, created_at=now(), vertices=character.n_vertices, faces=character.n_faces,
            bones=[], mesh=BlobRef(sha256=repository.storage.save_file(mesh, ".obj").sha256, suffix=".obj"))
        repository.put(record, record.id)
        records[name] = record
    style = add_hairstyle(repository, records["source"], world["hair"], tmp_path / "groom.data", "h")
    assert style.options.anchoring == "auto"
    runner.run_preprocess(repository, settings, style.id)
    assert repository.preprocessing_status(style).state == "ready", repository.preprocessing_status(style).error
    world["ids"]["bare"], world["ids"]["bare-target"] = style, records["target"]
    job = add_job(world, target="bare-target", hairstyle="bare")
    runner.run_retarget(repository, settings, job.id, "w1")
    job = repository.job(job.id)
    assert job.state == "succeeded", job.error
    assert job.metrics["anchoring"] == "surface" and job.metrics["penetrating_particles"] == 0
    assert job.metrics["fallback_anchors"] == int((~world["hair"].is_root).sum())


def test_only_the_current_message_starts_a_job_and_only_once(world):
    """Task ids as attempt tokens: an older message, or a second delivery while a live run has the job,
    changes nothing; a run on this host whose process is gone is taken over at once."""
    repository, settings = world["repository"], world["settings"]
    job = add_job(world, task_id="current")
    runner.run_retarget(repository, settings, job.id, "w1", task_id="older")
    assert repository.job(job.id).state == "queued" and repository.job(job.id).attempts == 0
    live = {"state": "running", "attempts": 1, "run_token": "t1", "heartbeat_at": now(), "worker_host": runs.HOST,
            "worker_pid": os.getpid(), "started_at": now()}
    repository.set_job(job.id, **live)
    runner.run_retarget(repository, settings, job.id, "w2", task_id="current")
    assert repository.job(job.id).run_token == "t1" and repository.job(job.id).attempts == 1
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    repository.set_job(job.id, worker_pid=dead.pid)
    runner.run_retarget(repository, settings, job.id, "w2", task_id="current")
    done = repository.job(job.id)
    assert done.state == "succeeded" and done.attempts == 2 and done.worker == "w2" and done.run_token != "t1"


def test_a_job_whose_worker_died_max_attempts_times_fails_worker_lost(world):
    repository, settings = world["repository"], world["settings"]
    job = add_job(world, task_id="m", state="running", attempts=settings.max_attempts, run_token="t",
                  heartbeat_at=now() - settings.stale_after_seconds - 1, worker="w9@elsewhere")
    runner.run_retarget(repository, settings, job.id, "w1", task_id="m")
    failed = repository.job(job.id)
    assert failed.state == "failed" and failed.error.code == "worker_lost" and failed.attempts == 3
    assert "died 3 times" in failed.error.message and "w9@elsewhere" in failed.error.message
    assert failed.finished_at is not None and failed.outputs is None


def test_a_taken_over_run_writes_nothing_more(world):
    repository = world["repository"]
    job = add_job(world, state="running", run_token="mine")
    run = runs.OwnRun(lambda change: repository.change_job(job.id, change), "mine")
    assert run.beat() and repository.job(job.id).heartbeat_at is not None
    repository.set_job(job.id, run_token="theirs")
    assert not run.write(state="succeeded") and repository.job(job.id).state == "running"

