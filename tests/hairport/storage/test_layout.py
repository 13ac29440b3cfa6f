"""The storage layout: folders created, names checked, retention in seconds."""

import pytest

from hairport.storage import LocalStorage, blob_references, blob_relpath, check_sha256, check_suffix, retention_seconds


def test_layout_is_created(tmp_path):
    LocalStorage(tmp_path / "store")
    assert sorted(p.name for p in (tmp_path / "store").iterdir()) == ["blobs", "records", "tmp", "work"]


@pytest.mark.parametrize("bad", ["../x", "a/b", "", "x" * 65, "A", "a.json", "..", "a b"])
def test_invalid_kinds_and_ids_are_refused(tmp_path, bad):
    storage = LocalStorage(tmp_path)
    with pytest.raises(ValueError):
        storage.put_record("jobs", bad, {})
    with pytest.raises(ValueError):
        storage.put_record(bad, "ok", {})
    with pytest.raises(ValueError):
        storage.get_record("jobs", bad)
    with pytest.raises(ValueError):
        storage.update_record("jobs", bad, lambda doc: doc)
    with pytest.raises(ValueError):
        storage.delete_record("jobs", bad)
    with pytest.raises(ValueError):
        storage.list_records(bad)
    storage.put_record("jobs", "x" * 64, {"ok": True})  # 64 is the longest allowed
    assert storage.get_record("jobs", "x" * 64) == {"ok": True}


def test_blob_paths_suffixes_and_references():
    sha = "ab" + "0" * 62
    assert blob_relpath(sha, ".obj") == f"blobs/ab/{sha}.obj"
    assert check_sha256(sha) == sha and check_suffix(".tar.gz") == ".tar.gz" and check_suffix("") == ""
    for bad in ("../x", ".obj/..", "obj", ".o b", "." + "x" * 40):
        with pytest.raises(ValueError):
            check_suffix(bad)
    with pytest.raises(ValueError):
        check_sha256(sha.upper())
    document = {"mesh": {"sha256": sha}, "outputs": [{"sha256": "c" * 64}, {"other": 1}], "sha256": 7}
    assert blob_references(document) == {sha, "c" * 64}
    assert retention_seconds(1.5) == 1.5 * 86_400.0
