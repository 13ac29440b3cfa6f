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


#: integers no query may take: SQLite's and every 64-bit integer's overflow, and far beyond it
HUGE = (2**63, 10**30)


def integer_queries(document: dict) -> list[tuple[str, str, dict]]:
    """(path, parameter name, schema) of every integer query parameter of a GET operation."""
    found = []
    for path, methods in document["paths"].items():
        for parameter in methods.get("get", {}).get("parameters", ()):
            schema = parameter["schema"]
            branches = schema.get("anyOf", [schema])
            integer = next((branch for branch in branches if branch.get("type") == "integer"), None)
            if parameter["in"] == "query" and integer is not None:
                found.append((path, parameter["name"], integer))
    return found


def test_every_query_integer_is_bounded_and_out_of_range_is_422_never_500(client):
    from .conftest import AUTH
    from .routers.test_jobs import add_jobs

    job_id = add_jobs(client, 1)[0]
    document = client.get("/openapi.json").json()
    queries = integer_queries(document)
    assert {(path, name) for path, name, _ in queries} >= {
        ("/v1/jobs", "offset"), ("/v1/jobs", "limit"), ("/v1/batches", "offset"), ("/v1/characters", "offset"),
        ("/v1/hairstyles", "offset"), ("/v1/jobs/{job_id}/display", "strands")}
    for path, name, schema in queries:
        assert "maximum" in schema and "minimum" in schema, (path, name)
        url = path.replace("{job_id}", job_id)
        assert "422" in document["paths"][path]["get"]["responses"], (path, name)
        for value in (*HUGE, schema["maximum"] + 1, schema["minimum"] - 1):
            response = client.get(url, headers=AUTH, params={name: value})
            assert response.status_code == 422 and response.json()["code"] == "invalid_request", (path, name, value)
            assert name in response.json()["detail"]
        # the largest value is taken: a page (empty this far out), or the queued job's 409
        largest = client.get(url, headers=AUTH, params={name: schema["maximum"]})
        assert largest.status_code == (409 if "{job_id}" in path else 200), (path, name, largest.text)


def test_the_largest_offset_is_an_empty_page_with_the_total(client):
    from hairport.service.deps import MAX_OFFSET, MAX_PAGE

    from .conftest import AUTH
    from .routers.test_jobs import add_jobs

    add_jobs(client, 3)
    page = client.get("/v1/jobs", headers=AUTH, params={"offset": MAX_OFFSET, "limit": MAX_PAGE}).json()
    assert (page["jobs"], page["total"], page["offset"], page["next_offset"]) == ([], 3, MAX_OFFSET, None)
    assert MAX_OFFSET + MAX_PAGE < 2**31  # a signed 32-bit integer holds every offset and next_offset
