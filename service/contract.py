"""The OpenAPI document as the API keeps it: problems under their own schema, multipart forms
as clients send them, results under the media type of their format.

FastAPI writes the document from the routes; this module adds what it cannot know."""

from __future__ import annotations

from fastapi import FastAPI
from fastapi.openapi.utils import get_openapi

from .errors import PROBLEM_SCHEMA_REF
from .schemas import Problem

MULTIPART = "multipart/form-data"
#: FastAPI's default 422 schemas, unused once every route documents its 422 as a problem
FASTAPI_VALIDATION_SCHEMAS = ("HTTPValidationError", "ValidationError")


def install(app: FastAPI) -> None:
    """Serve the kept document at ``/openapi.json`` (and to ``hairport openapi``)."""

    def openapi() -> dict:
        if app.openapi_schema is None:
            document = get_openapi(title=app.title, version=app.version, description=app.description,
                                   routes=app.routes)
            app.openapi_schema = kept(document)
        return app.openapi_schema

    app.openapi = openapi


def kept(document: dict) -> dict:
    """FastAPI's document with the Problem schema, forms as they are read, and no unused 422 schemas."""
    schemas = document.setdefault("components", {}).setdefault("schemas", {})
    schemas[PROBLEM_SCHEMA_REF.rsplit("/", 1)[1]] = Problem.model_json_schema(
        ref_template="#/components/schemas/{model}")
    for operation in operations(document):
        form = operation.get("requestBody", {}).get("content", {}).get(MULTIPART)
        if form is not None:
            without_null(resolve(document, form["schema"]))
            files_as_files(resolve(document, form["schema"]))
            empty_is_not_given(resolve(document, form["schema"]))
    if not any(f"/{name}" in str(document["paths"]) for name in FASTAPI_VALIDATION_SCHEMAS):
        for name in FASTAPI_VALIDATION_SCHEMAS:
            schemas.pop(name, None)
    return document


def operations(document: dict):
    for methods in document["paths"].values():
        yield from methods.values()


def resolve(document: dict, schema: dict) -> dict:
    ref = schema.get("$ref")
    if ref is None:
        return schema
    node = document
    for part in ref.lstrip("#/").split("/"):
        node = node[part]
    return node


def is_file(field: dict) -> bool:
    return "contentMediaType" in field or field.get("format") == "binary"


def empty_is_not_given(form: dict) -> None:
    """A form field sent empty counts as not given (FastAPI's reading, and what an HTML form sends for an
    untouched input): an optional field's schema admits ``""`` next to its values, a required one
    demands at least one character."""
    required = set(form.get("required", ()))
    for name, field in form.get("properties", {}).items():
        if is_file(field):
            continue
        if name in required:
            if field.get("type") == "string":
                field.setdefault("minLength", 1)
        elif "enum" in field:
            field["enum"] = [*field["enum"], ""] if "" not in field["enum"] else field["enum"]
        elif field.get("type") in ("integer", "number"):
            value = {key: field.pop(key) for key in list(field) if key not in ("title", "description", "default")}
            field["anyOf"] = [value, dict(NOT_GIVEN)]


#: the schema of a form value sent empty
NOT_GIVEN = {"type": "string", "maxLength": 0, "description": "sent empty: not given"}


def files_as_files(form: dict) -> None:
    """A file field is documented as a file (Swagger UI then offers a file picker), though the API also
    reads a part sent without a file name as the file's text (``FilePart`` in service/uploads.py)."""
    for field in form.get("properties", {}).values():
        files = [branch for branch in field.get("anyOf", ()) if is_file(branch)]
        if files:
            del field["anyOf"]
            field.update(files[0])


def without_null(form: dict) -> None:
    """A multipart field is given or not: it cannot be null. FastAPI writes an optional field as
    ``anyOf [X, null]``, which makes a client (or a fuzzer) send the text ``null``; keep ``X``."""
    for field in form.get("properties", {}).values():
        branches = field.get("anyOf")
        if branches is None:
            continue
        kept_branches = [branch for branch in branches if branch.get("type") != "null"]
        if len(kept_branches) == 1:
            del field["anyOf"]
            field.update(kept_branches[0])
        else:
            field["anyOf"] = kept_branches
