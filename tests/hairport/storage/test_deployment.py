"""The deployment id: written once in the storage, the same for every process, naming the queues."""

import json
import multiprocessing
from concurrent.futures import ProcessPoolExecutor

import pytest

from hairport.storage import DEPLOYMENT_FILE, deployment_id, queue_name


def test_one_id_per_storage_even_when_processes_race(tmp_path):
    # spawned, as workers on a host are (and never forked from a process that ran the solver's threads)
    with ProcessPoolExecutor(4, mp_context=multiprocessing.get_context("spawn")) as pool:
        ids = set(pool.map(deployment_id, [tmp_path / "a"] * 8))
    assert len(ids) == 1 and json.loads((tmp_path / "a" / DEPLOYMENT_FILE).read_text())["id"] in ids
    assert deployment_id(tmp_path / "b") not in ids
    assert [path.name for path in (tmp_path / "a").iterdir()] == [DEPLOYMENT_FILE]  # no temporary left
    with pytest.raises(FileNotFoundError):
        deployment_id(tmp_path / "c", create=False)


def test_queue_names_are_namespaced_and_checked():
    assert queue_name("0a1b2c", "retarget") == "hairport.0a1b2c.retarget"
    with pytest.raises(ValueError):
        queue_name("../x", "retarget")
