"""``/v1/hairstyles``: upload a hair file for a source character; preprocessing runs once per content."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, File, Form, UploadFile

from hairport.solver import pipeline
from hairport.worker import jobs

from ..auth import Owner
from ..deps import SettingsDep, StorageDep, owned_record
from ..errors import Problem
from ..schemas import HairstyleOut
from ..uploads import extension_of, input_problem, store_upload, validated
from .characters import UNITS, owned_character

router = APIRouter(prefix="/v1/hairstyles", tags=["hairstyles"])


def hairstyle_out(storage, record: dict) -> HairstyleOut:
    return HairstyleOut(
        id=record["id"], source_character_id=record["source_character_id"], strands=record["strands"],
        particles=record["particles"], sha256=record["hair"]["sha256"], format=record["format"],
        units=record["units"], options=record["options"], preprocessing=jobs.preprocessing_status(storage, record),
        created_at=record["created_at"],
    )


def owned_hairstyle(storage, owner: str, hairstyle_id: str) -> dict:
    return owned_record(storage, "hairstyles", owner, hairstyle_id, "hairstyle")


@router.post("", status_code=201, response_model=HairstyleOut, summary="Upload a hairstyle")
async def create_hairstyle(
    owner: Owner,
    settings: SettingsDep,
    storage: StorageDep,
    hair: Annotated[UploadFile, File(description="hair file: .data, .hair, .ply, .npz or .obj")],
    source_character_id: Annotated[str, Form(description="the character the hairstyle was made for")],
    units: Annotated[str, Form(description="units of the hair file")] = "m",
    guides: Annotated[int | None, Form(description="guide strands of the multi-scale solve (default 300)")] = None,
    k: Annotated[int, Form(description="inter-strand neighbours per particle (Eq. 8)")] = 5,
) -> HairstyleOut:
    if units not in UNITS:
        raise Problem(422, "bad_units", f"units must be one of {', '.join(UNITS)}")
    character = owned_character(storage, owner, source_character_id)
    if not character["bones"]:
        raise Problem(422, "no_skeleton", "the source character needs a skeleton (skeleton JSON or glTF skin)")
    options = pipeline.PreprocessOptions(k=k, guides=pipeline.DEFAULT_GUIDES if guides is None else guides)
    try:
        options.validate()
    except pipeline.InputError as error:
        raise input_problem(error, "options") from None
    suffix = extension_of(hair, tuple(f".{f}" for f in pipeline.HAIR_FORMATS), "hair")
    blob = await store_upload(storage, hair, settings, suffix, "hair")
    options_doc = {"k": options.k, "guides": options.guides}
    key = jobs.artifact_key(character, blob.sha256, units, options_doc, pipeline.ARTIFACT_FORMAT_VERSION)
    hairstyle_id = jobs.owned_id(owner, key)
    record = storage.get_record("hairstyles", hairstyle_id)
    if record is None:
        loaded = await validated(
            pipeline.read_hair_file, "hair", blob.path, units, max_strands=settings.max_strands,
            max_particles=settings.max_particles, max_bytes=settings.max_upload_bytes,
        )
        record = {
            "id": hairstyle_id, "owner": owner, "created_at": jobs.now(), "source_character_id": character["id"],
            "hair": {"sha256": blob.sha256, "suffix": suffix, "size": blob.size}, "format": suffix[1:],
            "units": units, "options": options_doc, "artifact_key": key,
            "strands": int(loaded.n_strands), "particles": int(loaded.n_particles),
        }
        storage.put_record("hairstyles", hairstyle_id, record)
    if jobs.preprocessing_status(storage, record)["state"] in (jobs.QUEUED, jobs.FAILED):
        jobs.start_preprocessing(storage, record)
    return hairstyle_out(storage, record)


@router.get("/{hairstyle_id}", response_model=HairstyleOut, summary="A hairstyle and its preprocessing state")
def get_hairstyle(owner: Owner, storage: StorageDep, hairstyle_id: str) -> HairstyleOut:
    return hairstyle_out(storage, owned_hairstyle(storage, owner, hairstyle_id))
