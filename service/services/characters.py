"""Characters: a body mesh and its skeleton, stored content-addressed per owner."""

from __future__ import annotations

from fastapi import UploadFile

from hairport import solver
from hairport.records import BlobRef, CharacterRecord, digest, now, owned_id
from hairport.repository import Repository
from hairport.settings import Settings

from ..errors import Problem
from ..uploads import check_axis, check_units, extension_of, store_upload, validated

SKELETON_SUFFIX = ".json"


async def create_character(repository: Repository, settings: Settings, owner: str, mesh: UploadFile,
                           skeleton: UploadFile | None, units: str | None, up_axis: str | None = None,
                           front_axis: str | None = None) -> CharacterRecord:
    """Store and validate an uploaded character; the same upload twice gives the same record.

    ``units`` None or ``auto``: the units its files state, else inferred when it is used; the
    axes likewise (``None``: inferred)."""
    check_units(units)
    units = None if units == solver.AUTO else units
    up_axis, front_axis = check_axis(up_axis, "up_axis"), check_axis(front_axis, "front_axis")
    if up_axis and front_axis and up_axis[1] == front_axis[1]:
        raise Problem(422, "bad_axis", "up_axis and front_axis must be perpendicular")
    axes = [up_axis, front_axis] if up_axis or front_axis else []
    suffix = extension_of(mesh, solver.MESH_EXTENSIONS, "mesh")
    if skeleton is not None:
        extension_of(skeleton, (SKELETON_SUFFIX,), "skeleton")
    storage = repository.storage
    mesh_blob = await store_upload(storage, mesh, settings, suffix, "mesh")
    try:
        skeleton_blob = await store_upload(storage, skeleton, settings, SKELETON_SUFFIX, "skeleton") if skeleton else None
    except Problem:
        storage.discard_new(mesh_blob)
        raise
    character_id = owned_id(owner, digest(
        "character", mesh_blob.sha256, suffix, skeleton_blob.sha256 if skeleton_blob else None, units, *axes))
    existing = repository.get(CharacterRecord, character_id)
    if existing is not None:
        return existing
    try:
        character = await validated(
            settings, "character", "mesh", mesh=str(mesh_blob.path),
            skeleton=str(skeleton_blob.path) if skeleton_blob else None, units=units,
            max_vertices=settings.max_vertices, max_faces=settings.max_faces, max_bytes=settings.max_upload_bytes,
        )
    except Problem:
        storage.discard_new(mesh_blob, skeleton_blob)  # a refused upload keeps no file
        raise
    record = CharacterRecord(
        id=character_id, owner=owner, created_at=now(),
        mesh=BlobRef(sha256=mesh_blob.sha256, suffix=suffix, size=mesh_blob.size),
        skeleton=BlobRef(sha256=skeleton_blob.sha256, suffix=SKELETON_SUFFIX) if skeleton_blob else None,
        units=character["units"], up_axis=up_axis, front_axis=front_axis,
        vertices=character["vertices"], faces=character["faces"], bones=character["bones"],
    )
    repository.put(record, character_id)
    return record
