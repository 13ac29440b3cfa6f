"""The per-target cache (worker/bodies.py): a body's collision surface is built once, kept in the storage by
content, read back by every later job (another process's too), rebuilt when its file is damaged."""

import numpy as np

from hairport import solver
from hairport.records import BodyRecord
from hairport.worker import bodies, runner

from .test_runner import add_job, world  # noqa: F401 - the storage with toy characters and a preprocessed groom


def target_of(world):  # noqa: F811
    repository = world["repository"]
    job = add_job(world)
    from hairport.worker.loading import job_inputs

    _, target, _ = job_inputs(repository, world["settings"], job, repository.artifact(job.artifact_key))
    return target


def test_a_body_is_built_once_and_read_back_by_content(world):  # noqa: F811
    repository, settings = world["repository"], world["settings"]
    target = target_of(world)
    key = solver.body_key(target.vertices, target.faces)
    repository.storage.delete_record(BodyRecord.KIND, key)
    built, timings = bodies.collision_surface(repository, settings, target)
    assert set(timings) == {bodies.BUILT} and timings[bodies.BUILT] > 0
    np.testing.assert_array_equal(built, solver.collision_faces(target.vertices, target.faces))
    record = repository.get(BodyRecord, key)
    assert record.faces == target.n_faces and record.seconds > 0
    loaded, timings = bodies.collision_surface(repository, settings, target)
    assert set(timings) == {bodies.LOADED} and np.array_equal(loaded, built)
    off = settings.model_copy(update={"target_cache": False})
    assert bodies.collision_surface(repository, off, target) == (None, {})


def test_a_damaged_surface_file_is_built_again(world, tmp_path):  # noqa: F811
    repository, settings = world["repository"], world["settings"]
    target = target_of(world)
    bodies.collision_surface(repository, settings, target)
    record = repository.get(BodyRecord, solver.body_key(target.vertices, target.faces))
    np.save(tmp_path / "short.npy", np.ones(3, dtype=bool))
    short = repository.storage.save_file(tmp_path / "short.npy", ".npy")
    repository.put(record.model_copy(update={"sha256": short.sha256}), record.key)
    surface, timings = bodies.collision_surface(repository, settings, target)
    assert set(timings) == {bodies.BUILT} and surface.shape == (target.n_faces,)
    assert repository.get(BodyRecord, record.key).sha256 == record.sha256  # the good file is kept again


def test_a_job_shows_what_the_cache_did_in_its_timings(world):  # noqa: F811
    repository, settings = world["repository"], world["settings"]
    target = target_of(world)
    repository.storage.delete_record(BodyRecord.KIND, solver.body_key(target.vertices, target.faces))
    first, second = add_job(world), add_job(world)
    runner.run_retarget(repository, settings, first.id, "w@h")
    runner.run_retarget(repository, settings, second.id, "w@h")
    assert bodies.BUILT in repository.job(first.id).timings and bodies.LOADED in repository.job(second.id).timings
    a, b = (solver.read_hair(repository.storage.blob(repository.job(job.id).outputs["npz"].sha256, ".npz").path)
            for job in (first, second))
    np.testing.assert_array_equal(a.points, b.points)
