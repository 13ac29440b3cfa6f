"""The wrap cache (worker/wraps.py): a job onto a target of another topology wraps the source body once, keeps the
wrap in the storage by its key, and every later job of that groom and target reads it back; the job's
progress shows the wrap; a damaged file is wrapped again; the cache off wraps every time."""

import numpy as np
import pytest

from hairport import solver
from hairport.records import BlobRef, CharacterRecord, WrapRecord, now
from hairport.repository import Repository
from hairport.settings import Settings
from hairport.solver.io.character.obj import write_obj
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import PRESETS, build_character, write_character
from hairport.solver.synthetic.remesh import remeshed_character
from hairport.storage import LocalStorage
from hairport.worker import runner, wraps
from hairport.worker.loading import job_inputs

from .test_runner import OWNER, add_hairstyle, add_job


@pytest.fixture(scope="module")
def world(tmp_path_factory):
    """A storage with the average MakeHuman female and a 40-strand groom (preprocessed), and the heavy male
    remeshed to 5,000 vertices, without a rig (another topology)."""
    root = tmp_path_factory.mktemp("wraps")
    repository = Repository(LocalStorage(root / "storage", durable=False))
    settings = Settings(storage_dir=root / "storage")
    source = build_character(PRESETS["average-female"])
    write_character(source, root / "source.obj", root / "source.skeleton.json")
    male = remeshed_character(build_character(PRESETS["heavy-male"]), 5000, seed=2)
    write_obj(root / "male.obj", male.vertices, male.faces, "the heavy male remeshed")
    ids = {}
    for letter, name, skeleton in (("1", "source", root / "source.skeleton.json"), ("2", "male", None)):
        character = source if name == "source" else male
        record = CharacterRecord(
            id=letter * 32, owner=OWNER, created_at=now(), vertices=character.n_vertices, faces=character.n_faces,
            bones=list(character.skeleton.names) if skeleton else [], units="m",
            mesh=BlobRef(sha256=repository.storage.save_file(root / f"{name}.obj", ".obj").sha256, suffix=".obj"),
            skeleton=None if skeleton is None else BlobRef(
                sha256=repository.storage.save_file(skeleton, ".json").sha256, suffix=".json"))
        repository.put(record, record.id)
        ids[name] = record
    ids["hairstyle"] = add_hairstyle(repository, ids["source"], generate_groom(source, "short", 40, 6, seed=3),
                                     root / "groom.data", "a")
    runner.run_preprocess(repository, settings, ids["hairstyle"].id)
    return {"repository": repository, "settings": settings, "ids": ids, "root": root}


def forget_the_wrap(world) -> str:
    """The key of the world's wrap, its record removed."""
    repository = world["repository"]
    job = add_job(world, target="male")
    adaptable, target, _ = job_inputs(repository, world["settings"], job, repository.artifact(job.artifact_key))
    key = solver.wrap_key(adaptable, target)
    repository.storage.delete_record(WrapRecord.KIND, key)
    return key


def result_points(repository, job) -> np.ndarray:
    done = repository.job(job.id)
    return solver.read_hair(repository.storage.blob(done.outputs["npz"].sha256, ".npz").path).points


def test_a_job_wraps_once_and_the_next_reads_the_wrap(world, monkeypatch):
    repository, settings = world["repository"], world["settings"]
    key = forget_the_wrap(world)
    stages = []
    original = runner.JobProgress.__call__
    monkeypatch.setattr(runner.JobProgress, "__call__", lambda self, stage, fraction, message: (
        stages.append((stage, message)), original(self, stage, fraction, message)))
    first, second = add_job(world, target="male"), add_job(world, target="male")
    runner.run_retarget(repository, settings, first.id, "w@h")
    made = repository.job(first.id)
    assert made.state == "succeeded", made.error
    assert {"wrap", wraps.STORED} <= set(made.timings) and wraps.LOADED not in made.timings
    assert made.metrics["penetrating_particles"] == 0 and made.metrics["wrap"]["residual_m"]["mean"] < 2e-3
    assert made.metrics["input"]["target"]["topology"] == "other"
    record = repository.get(WrapRecord, key)
    assert record.vertices == 13380 and record.seconds == made.metrics["wrap"]["seconds"]
    assert any(stage == "wrap" and "wrapping" in message for stage, message in stages)

    stages.clear()
    runner.run_retarget(repository, settings, second.id, "w@h")
    read = repository.job(second.id)
    assert read.state == "succeeded" and wraps.LOADED in read.timings
    assert "wrap" not in read.timings and wraps.STORED not in read.timings
    assert read.timings[wraps.LOADED] < 0.5 * made.timings["wrap"]
    assert any(stage == "wrap" and "from the cache" in message for stage, message in stages)
    assert read.metrics["wrap"] == made.metrics["wrap"]
    np.testing.assert_array_equal(result_points(repository, first), result_points(repository, second))


def test_a_damaged_wrap_file_is_wrapped_again(world, tmp_path):
    repository, settings = world["repository"], world["settings"]
    key = forget_the_wrap(world)
    runner.run_retarget(repository, settings, add_job(world, target="male").id, "w@h")
    record = repository.get(WrapRecord, key)
    np.savez(tmp_path / "short.npz", vertices=np.zeros((3, 3)), report=np.array("{}"))
    short = repository.storage.save_file(tmp_path / "short.npz", ".npz")
    repository.put(record.model_copy(update={"sha256": short.sha256}), key)
    job = add_job(world, target="male")
    runner.run_retarget(repository, settings, job.id, "w@h")
    again = repository.job(job.id)
    assert again.state == "succeeded" and "wrap" in again.timings and wraps.LOADED not in again.timings
    kept = repository.get(WrapRecord, key)  # a good file is kept again
    with np.load(repository.storage.blob(kept.sha256, kept.suffix).path) as stored:
        assert stored["vertices"].shape == (13380, 3) and "residual_m" in str(stored["report"])


def test_with_the_cache_off_every_job_wraps(world):
    repository = world["repository"]
    off = world["settings"].model_copy(update={"target_cache": False})
    key = forget_the_wrap(world)
    job = add_job(world, target="male")
    runner.run_retarget(repository, off, job.id, "w@h")
    done = repository.job(job.id)
    assert done.state == "succeeded" and "wrap" in done.timings and repository.get(WrapRecord, key) is None
    assert not {wraps.LOADED, wraps.STORED} & set(done.timings)


def test_a_target_of_the_sources_topology_has_no_wrap(world):
    repository, settings = world["repository"], world["settings"]
    job = add_job(world, target="source")
    adaptable, target, _ = job_inputs(repository, settings, job, repository.artifact(job.artifact_key))
    assert wraps.cached_wrap(repository, settings, adaptable, target, "auto") == (None, {})
    assert wraps.keep(repository, settings, None) == {}


def test_a_target_that_cannot_be_wrapped_fails_the_job_with_wrap_failed(world, tmp_path):
    import trimesh

    repository, settings = world["repository"], world["settings"]
    ball = trimesh.creation.icosphere(subdivisions=4, radius=0.11)
    write_obj(tmp_path / "ball.obj", np.asarray(ball.vertices) + [0.0, 0.75, 0.0], np.asarray(ball.faces), "a ball")
    record = CharacterRecord(
        id="3" * 32, owner=OWNER, created_at=now(), vertices=len(ball.vertices), faces=len(ball.faces), bones=[],
        mesh=BlobRef(sha256=repository.storage.save_file(tmp_path / "ball.obj", ".obj").sha256, suffix=".obj"))
    repository.put(record, record.id)
    world["ids"]["ball"] = record
    job = add_job(world, target="ball")
    runner.run_retarget(repository, settings, job.id, "w@h")
    failed = repository.job(job.id)
    assert failed.state == "failed" and failed.error.code == "wrap_failed" and failed.outputs is None
    assert "could not be wrapped" in failed.error.message and "give the character's up_axis" in failed.error.message
    assert "/blobs/" not in failed.error.message


def test_a_jobs_landmarks_steer_its_wrap_which_is_kept_under_its_own_key(world):
    repository, settings = world["repository"], world["settings"]
    source, male = build_character(PRESETS["average-female"]), build_character(PRESETS["heavy-male"])
    crown, ear = int(np.argmax(source.vertices[:, 1])), int(np.argmax(source.vertices[:, 0] * (source.vertices[:, 1] > 1.5)))
    marks = {"source": {"crown": source.vertices[crown].tolist(), "ear": source.vertices[ear].tolist()},
             "target": {"crown": male.vertices[crown].tolist(), "ear": male.vertices[ear].tolist()}}
    job = add_job(world, target="male", landmarks=marks)
    runner.run_retarget(repository, settings, job.id, "w@h")
    done = repository.job(job.id)
    assert done.state == "succeeded", done.error
    wrap = done.metrics["wrap"]
    assert set(wrap["landmark_errors_m"]) == {"crown", "ear"} and max(wrap["landmark_errors_m"].values()) < 1e-3
    adaptable, target, found = job_inputs(repository, settings, done, repository.artifact(done.artifact_key))
    landmarks = solver.landmarks_in_canonical(solver.LandmarkPairs.from_document(marks), adaptable, found)
    key = solver.wrap_key(adaptable, target, landmarks=landmarks)
    assert key != solver.wrap_key(adaptable, target) and repository.get(WrapRecord, key) is not None
    # a landmark far off the target (given in millimetres) fails the job by name, with nothing written
    far = {**marks, "target": {name: [1000.0 * v for v in point] for name, point in marks["target"].items()}}
    job = add_job(world, target="male", landmarks=far)
    runner.run_retarget(repository, settings, job.id, "w@h")
    failed = repository.job(job.id)
    assert failed.state == "failed" and failed.error.code == "bad_landmarks" and failed.outputs is None
    assert "from the target body" in failed.error.message
