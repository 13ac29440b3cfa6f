"""Indexes: one empty file per entry, retagged by rename, listed without reading documents."""

import pytest

from hairport.storage import LocalStorage


def names(storage: LocalStorage, index: str, group: str) -> list[str]:
    return sorted(p.name for p in (storage.root / "index" / index / group).iterdir())


def test_put_list_retag_and_drop(tmp_path):
    storage = LocalStorage(tmp_path)
    storage.index_put("jobs", "owner-a", "0001-j1", "queued")
    storage.index_put("jobs", "owner-a", "0002-j2", "queued")
    storage.index_put("jobs", "owner-b", "0003-j3", "failed")
    assert sorted(storage.index_entries("jobs", "owner-a")) == [("0001-j1", "queued"), ("0002-j2", "queued")]
    assert storage.index_groups("jobs") == ["owner-a", "owner-b"]
    storage.index_put("jobs", "owner-a", "0001-j1", "running", old_tag="queued")
    assert names(storage, "jobs", "owner-a") == ["0001-j1.running", "0002-j2.queued"]
    # without the old tag (or with a wrong one) the entry is found by its key: still one entry
    storage.index_put("jobs", "owner-a", "0001-j1", "succeeded", old_tag="cancelled")
    storage.index_put("jobs", "owner-a", "0002-j2", "failed")
    assert names(storage, "jobs", "owner-a") == ["0001-j1.succeeded", "0002-j2.failed"]
    storage.index_put("jobs", "owner-a", "0002-j2", "failed")  # same tag: unchanged
    assert names(storage, "jobs", "owner-a") == ["0001-j1.succeeded", "0002-j2.failed"]
    storage.index_drop("jobs", "owner-a", "0001-j1")
    assert storage.index_entries("jobs", "owner-a") == [("0002-j2", "failed")]


def test_empty_and_missing_groups(tmp_path):
    storage = LocalStorage(tmp_path)
    assert storage.index_entries("jobs", "nobody") == []
    assert storage.index_groups("jobs") == []
    storage.index_drop("jobs", "nobody", "k")  # nothing to drop: no error


@pytest.mark.parametrize("bad", ["../x", "a/b", "", "A", "a b", "x" * 65])
def test_names_are_checked(tmp_path, bad):
    storage = LocalStorage(tmp_path)
    for call in (lambda: storage.index_put(bad, "g", "k", "t"), lambda: storage.index_put("i", bad, "k", "t"),
                 lambda: storage.index_put("i", "g", bad, "t"), lambda: storage.index_put("i", "g", "k", bad)):
        with pytest.raises(ValueError):
            call()
    assert not (tmp_path / "index" / "i").exists() or list((tmp_path / "index" / "i").rglob("*.t")) == []
