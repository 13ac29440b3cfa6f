"""What a job's run reads (worker/loading.py): stored inputs by record, and the error a job reports."""

import pytest
from celery.exceptions import SoftTimeLimitExceeded

from hairport import solver
from hairport.records import BlobRef
from hairport.worker import loading

from .test_runner import add_job, world  # noqa: F401 - the storage with toy characters and a preprocessed groom


def test_memory_error_is_over_memory_budget():
    info = loading.error_info(MemoryError(), 10)
    assert info.code == loading.OVER_MEMORY_BUDGET == "over_memory_budget" and "MEMORY_BUDGET" in info.message


def test_bad_input_reports_its_problem_and_code_without_its_source():
    info = loading.error_info(solver.InputError("3 strands have NaN", "/srv/storage/blobs/ab/abcd.npz", "non_finite"), 10)
    assert (info.code, info.message) == ("non_finite", "3 strands have NaN")
    assert loading.error_info(SoftTimeLimitExceeded(), 3300).message == "the job ran over its time limit (3300 s)"
    assert loading.error_info(KeyError("x"), 10).code == "internal"


def test_a_purged_input_is_gone_and_a_job_reads_its_groom_and_target(world):  # noqa: F811
    repository = world["repository"]
    with pytest.raises(solver.InputError) as error:
        loading.blob_path(repository, BlobRef(sha256="0" * 64, suffix=".obj"))
    assert error.value.code == "gone"
    assert loading.blob_path(repository, None) is None
    job = add_job(world)
    adaptable, target, _ = loading.job_inputs(repository, world["settings"], job, repository.artifact(job.artifact_key))
    assert adaptable.hair.n_strands == 30 and target.n_vertices == world["ids"]["target"].vertices
    assert loading.adaptable_at.cache_info().currsize >= 1  # kept loaded for the next job of the same groom
