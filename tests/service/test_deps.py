"""Owned resources: anything the caller does not own, or that cannot exist, is 404."""

import pytest

from hairport.records import BlobRef, CharacterRecord
from hairport.repository import Repository
from hairport.service.deps import owned
from hairport.service.errors import Problem
from hairport.storage import LocalStorage


def test_owned_records(tmp_path):
    repository = Repository(LocalStorage(tmp_path))
    record = CharacterRecord(id="c" * 32, owner="kmine", created_at=0.0, mesh=BlobRef(sha256="a" * 64), vertices=3,
                             faces=1, bones=[])
    repository.put(record, record.id)
    assert owned(repository, CharacterRecord, "kmine", "c" * 32, "character") == record
    for owner, record_id in (("ktheirs", "c" * 32), ("kmine", "d" * 32), ("kmine", "../etc"), ("kmine", "C" * 32),
                             ("kmine", "c" * 65), ("kmine", "")):
        with pytest.raises(Problem) as refused:
            owned(repository, CharacterRecord, owner, record_id, "character")
        assert (refused.value.status, refused.value.code) == (404, "not_found")
