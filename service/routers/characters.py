"""``/v1/characters``: upload a body mesh (and its skeleton); content-addressed per key."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, File, Form, Response

from hairport.records import CharacterRecord
from hairport.solver import display as wire

from ..auth import Owner
from ..deps import DEFAULT_PAGE, OwnedCharacter, PageLimit, PageOffset, RepositoryDep, SettingsDep
from ..errors import problem_responses
from ..schemas import AXIS_ENUM, DISPLAY_RESPONSE, MESH_FILE_DESCRIPTION, UNITS_ENUM, CharacterOut, CharacterPage
from ..services import characters, display
from ..uploads import FilePart, as_upload

router = APIRouter(prefix="/v1/characters", tags=["characters"])


@router.post("", status_code=201, response_model=CharacterOut, summary="Upload a character",
             responses=problem_responses(400, 401, 413, 415, 422, 503))
async def create_character(
    owner: Owner,
    settings: SettingsDep,
    repository: RepositoryDep,
    mesh: Annotated[FilePart, File(description=MESH_FILE_DESCRIPTION)],
    skeleton: Annotated[FilePart | None, File(description="skeleton JSON (or use the glTF skin)")] = None,
    units: Annotated[str | None, Form(description="units of a mesh without a skeleton JSON (default auto: glTF's "
                                                  "meters, else inferred from sizes)",
                                                  json_schema_extra=UNITS_ENUM)] = None,
    up_axis: Annotated[str | None, Form(description="the mesh's up axis: x, y, z, -x, -y, -z "
                                                    "(default auto: inferred)", json_schema_extra=AXIS_ENUM)] = None,
    front_axis: Annotated[str | None, Form(description="the axis the face looks along (default auto: inferred)",
                                           json_schema_extra=AXIS_ENUM)] = None,
) -> CharacterOut:
    return CharacterOut.of(await characters.create_character(repository, settings, owner, as_upload(mesh),
                                                             as_upload(skeleton), units,
                                                             up_axis, front_axis))


@router.get("", response_model=CharacterPage, summary="The caller's characters, newest first",
            responses=problem_responses(401, 422))
def list_characters(owner: Owner, repository: RepositoryDep, limit: PageLimit = DEFAULT_PAGE,
                    offset: PageOffset = 0) -> CharacterPage:
    page, total = repository.list_owned(CharacterRecord, owner, limit, offset)
    return CharacterPage(characters=[CharacterOut.of(record) for record in page], total=total, limit=limit,
                         offset=offset, next_offset=offset + limit if offset + limit < total else None)


@router.get("/{character_id}/mesh", summary="The character's mesh for drawing (its own units and axes)",
            response_class=Response, responses={**DISPLAY_RESPONSE, **problem_responses(401, 404, 410, 422)})
def get_mesh(repository: RepositoryDep, settings: SettingsDep, character: OwnedCharacter):
    return Response(display.character_mesh(repository, settings, character), media_type=wire.MEDIA_TYPE)


@router.get("/{character_id}", response_model=CharacterOut, summary="A character",
            responses=problem_responses(401, 404, 422))
def get_character(character: OwnedCharacter) -> CharacterOut:
    return CharacterOut.of(character)
