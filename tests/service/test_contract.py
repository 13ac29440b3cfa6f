"""The OpenAPI document says what the API does: every problem a route raises is documented under
``application/problem+json`` with the Problem schema, forms as they are read, results by format."""

import re
from pathlib import Path

import pytest

from hairport.service import errors
from hairport.service.schemas import RESULT_MEDIA_TYPES

from .conftest import AUTH
from .routers.uploads import upload_character, write_inputs

SERVICE = Path(errors.__file__).parent
#: a problem raised in the service's source: Problem(404, "not_found", ...) / problem_response(413, "...", ...)
RAISED = re.compile(r"""(?:Problem|problem_response)\(\s*(\d{3}),\s*"([a-z_]+)\"""")


def test_every_problem_the_service_raises_is_documented_with_its_code():
    raised = {(int(status), code) for path in SERVICE.rglob("*.py")
              for status, code in RAISED.findall(path.read_text())}
    assert len(raised) >= 12
    raised |= {(status, code) for status, code in errors._HTTP_CODES.items()}
    undocumented = {(status, code) for status, code in raised
                    if code not in errors.PROBLEM_STATUSES.get(status, ("", ()))[1]}
    assert undocumented == set()


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    return write_inputs(tmp_path_factory.mktemp("contract"))


def test_the_api_document_lists_every_status_and_code():
    # the README's error table lists every code with its status too (tests/test_docs.py)
    api = (Path(__file__).parents[2] / "docs" / "api.md").read_text()
    for status, (_, codes) in errors.PROBLEM_STATUSES.items():
        row = next(line for line in api.splitlines() if line.startswith(f"| {status} |"))
        assert all(f"`{code}`" in row for code in codes), status


def test_every_error_response_is_a_problem(client):
    document = client.get("/openapi.json").json()
    assert "HTTPValidationError" not in document["components"]["schemas"]
    assert set(document["components"]["schemas"]["Problem"]["required"]) == {"type", "title", "status", "detail",
                                                                              "code"}
    counted = 0
    for path, methods in document["paths"].items():
        for method, operation in methods.items():
            statuses = {int(status) for status in operation["responses"] if int(status) >= 400}
            if path.startswith("/v1/"):
                assert {401, 422} <= statuses, (method, path)
                assert operation["security"] == [{"bearer": []}, {"apiKey": []}]
            if "_id}" in path or method == "post" and path != "/v1/characters":
                assert 404 in statuses, (method, path)
            for status in statuses - {503} if path == "/readyz" else statuses:
                content = operation["responses"][str(status)]["content"]
                assert content == {"application/problem+json": {"schema": {"$ref": "#/components/schemas/Problem"}}}
                counted += 1
    assert counted >= 40
    submits = [document["paths"][path]["post"]["responses"]["503"] for path in ("/v1/retargets", "/v1/hairstyles")]
    assert all("Retry-After" in response["headers"] and "queue_unavailable" in response["description"]
               for response in submits)
    assert "over_memory_budget" in document["paths"]["/v1/hairstyles"]["post"]["responses"]["413"]["description"]


def test_a_result_is_documented_under_the_media_type_of_each_format(client):
    result = client.get("/openapi.json").json()["paths"]["/v1/jobs/{job_id}/result"]["get"]["responses"]["200"]
    assert set(result["content"]) == {"application/octet-stream", "model/obj", "model/vnd.usda"} == set(RESULT_MEDIA_TYPES.values())
    assert "obj `model/obj`" in result["description"] and "usda `model/vnd.usda`" in result["description"]


def test_a_form_field_sent_empty_is_not_given(client, files):
    given = {"mesh": ("toy.obj", files["source.obj"])}
    plain = client.post("/v1/characters", headers=AUTH, files=given)
    empty = client.post("/v1/characters", headers=AUTH, files=given, data={"units": "", "up_axis": "",
                                                                           "front_axis": ""})
    assert (plain.status_code, empty.status_code) == (201, 201) and empty.json() == plain.json()
    source = upload_character(client, files, "source")
    hair = {"hair": ("g.data", files["groom.data"])}
    both = [client.post("/v1/hairstyles", headers=AUTH, files=hair, data={"source_character_id": source, **extra})
            for extra in ({}, {"units": "", "guides": "", "k": "", "anchoring": ""})]
    assert [response.status_code for response in both] == [201, 201] and both[0].json() == both[1].json()
    missing = client.post("/v1/hairstyles", headers=AUTH, files=hair, data={"source_character_id": ""})
    assert (missing.status_code, missing.json()["code"]) == (422, "invalid_request")
    assert "source_character_id" in missing.json()["detail"]
    schema = client.get("/openapi.json").json()["components"]["schemas"]["Body_create_hairstyle_v1_hairstyles_post"]
    assert schema["properties"]["source_character_id"]["minLength"] == 1 and "" in schema["properties"]["units"]["enum"]


def test_a_file_without_an_extension_is_recognised_by_its_content(client, files):
    named = client.post("/v1/characters", headers=AUTH, files={"mesh": ("toy.obj", files["source.obj"]),
                                                                "skeleton": ("s.json", files["source.skeleton.json"])})
    nameless = client.post("/v1/characters", headers=AUTH, files={"mesh": ("blob", files["source.obj"]),
                                                                   "skeleton": ("", files["source.skeleton.json"])})
    assert (named.status_code, nameless.status_code) == (201, 201)
    assert nameless.json()["id"] == named.json()["id"]  # the same files: the same character
    as_fields = client.post("/v1/characters", headers=AUTH, data={
        "mesh": files["source.obj"].decode(), "skeleton": files["source.skeleton.json"].decode()})
    assert as_fields.status_code == 201 and as_fields.json()["id"] == named.json()["id"]  # curl -F 'mesh=<body.obj'
    binary = client.post("/v1/characters", headers=AUTH, data={"mesh": "\x00\x01glTF"})
    assert (binary.status_code, binary.json()["code"]) == (415, "unknown_format")
    source = named.json()["id"]
    data = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": source},
                       files={"hair": ("groom", files["groom.data"])})  # .data has no signature
    assert (data.status_code, data.json()["code"]) == (415, "unknown_format")
    assert "name the file with its extension" in data.json()["detail"]
    foreign = client.post("/v1/characters", headers=AUTH, files={"mesh": ("toy.stl", files["source.obj"])})
    assert (foreign.status_code, foreign.json()["code"]) == (415, "unknown_format")  # the name says another format


def test_a_method_a_path_does_not_take_lists_those_it_takes(client):
    response = client.put("/v1/jobs/0123", headers=AUTH)
    assert (response.status_code, response.json()["code"]) == (405, "method_not_allowed")
    assert response.headers["allow"] == "DELETE, GET, HEAD"
    assert response.headers["content-type"] == "application/problem+json"
