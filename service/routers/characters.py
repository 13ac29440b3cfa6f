"""``/v1/characters``: upload a body mesh (and its skeleton); content-addressed per key."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, File, Form, UploadFile

from hairport.solver import pipeline
from hairport.worker import jobs

from ..auth import Owner
from ..deps import SettingsDep, StorageDep, owned_record
from ..errors import Problem
from ..schemas import CharacterOut
from ..uploads import extension_of, store_upload, validated

router = APIRouter(prefix="/v1/characters", tags=["characters"])
UNITS = ("m", "dm", "cm", "mm")


def character_out(record: dict) -> CharacterOut:
    return CharacterOut(
        id=record["id"], vertices=record["vertices"], faces=record["faces"], bones=record["bones"],
        has_skeleton=bool(record["bones"]), units=record["units"] or "m", sha256=record["mesh"]["sha256"],
        skeleton_sha256=(record.get("skeleton") or {}).get("sha256"), created_at=record["created_at"],
    )


def owned_character(storage, owner: str, character_id: str) -> dict:
    return owned_record(storage, "characters", owner, character_id, "character")


@router.post("", status_code=201, response_model=CharacterOut, summary="Upload a character")
async def create_character(
    owner: Owner,
    settings: SettingsDep,
    storage: StorageDep,
    mesh: Annotated[UploadFile, File(description="OBJ, PLY, GLB or glTF body mesh")],
    skeleton: Annotated[UploadFile | None, File(description="skeleton JSON (or use the glTF skin)")] = None,
    units: Annotated[str | None, Form(description="units of a mesh without a skeleton JSON (default m)")] = None,
) -> CharacterOut:
    if units is not None and units not in UNITS:
        raise Problem(422, "bad_units", f"units must be one of {', '.join(UNITS)}")
    suffix = extension_of(mesh, pipeline.MESH_EXTENSIONS, "mesh")
    if skeleton is not None:
        extension_of(skeleton, (".json",), "skeleton")
    mesh_blob = await store_upload(storage, mesh, settings, suffix, "mesh")
    skeleton_blob = await store_upload(storage, skeleton, settings, ".json", "skeleton") if skeleton else None
    character_id = jobs.owned_id(owner, jobs.digest(
        "character", mesh_blob.sha256, suffix, skeleton_blob.sha256 if skeleton_blob else None, units))
    existing = storage.get_record("characters", character_id)
    if existing is not None:
        return character_out(existing)
    character = await validated(
        pipeline.load_character_file, "mesh", mesh_blob.path, skeleton_blob.path if skeleton_blob else None, units,
        max_vertices=settings.max_vertices, max_faces=settings.max_faces, max_bytes=settings.max_upload_bytes,
    )
    record = {
        "id": character_id, "owner": owner, "created_at": jobs.now(),
        "mesh": {"sha256": mesh_blob.sha256, "suffix": suffix, "size": mesh_blob.size},
        "skeleton": {"sha256": skeleton_blob.sha256, "suffix": ".json"} if skeleton_blob else None,
        "units": units, "vertices": int(character.n_vertices), "faces": int(character.n_faces),
        "bones": list(character.skeleton.names) if character.skeleton is not None else [],
    }
    storage.put_record("characters", character_id, record)
    return character_out(record)


@router.get("/{character_id}", response_model=CharacterOut, summary="A character")
def get_character(owner: Owner, storage: StorageDep, character_id: str) -> CharacterOut:
    return character_out(owned_character(storage, owner, character_id))
