"""``/v1/hairstyles``: upload a hair file for a source character; preprocessing runs once per content."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, File, Form

from hairport import solver
from hairport.records import HairstyleRecord
from hairport.solver import options as solver_options

from ..auth import Owner
from ..deps import DEFAULT_PAGE, OwnedHairstyle, PageLimit, PageOffset, QueueDep, RepositoryDep, SettingsDep
from ..errors import problem_responses
from ..schemas import HAIR_FILE_DESCRIPTION, UNITS_ENUM, Anchoring, HairstyleOut, HairstylePage
from ..services import hairstyles
from ..uploads import FilePart, as_upload

router = APIRouter(prefix="/v1/hairstyles", tags=["hairstyles"])


def ranged_form(name: str, note: str = ""):
    """A form field bounded by the solver's range of option ``name`` (422 outside it)."""
    spec = solver_options.OPTION_RANGES[name]
    return Form(ge=spec.minimum, le=spec.maximum,
                description=f"{spec.description}; {spec.text()}" + (f" ({note})" if note else ""))
_DEFAULTS = solver.PreprocessOptions()
#: longest prim path a form accepts (USD paths are short; a longer value is refused at the door)
MAX_PRIM_CHARACTERS = 1024
#: longest attribute name (the hairstyle model's limit)
MAX_ATTRIBUTE_NAME = 128


@router.post("", status_code=201, response_model=HairstyleOut, summary="Upload a hairstyle",
             responses=problem_responses(400, 401, 404, 413, 415, 422, 503))
async def create_hairstyle(
    owner: Owner,
    settings: SettingsDep,
    repository: RepositoryDep,
    queue: QueueDep,
    hair: Annotated[FilePart, File(description=HAIR_FILE_DESCRIPTION)],
    source_character_id: Annotated[str, Form(description="the character the hairstyle was made for", min_length=1)],
    units: Annotated[str, Form(description="units of the hair file (default auto: those a .npz records, else "
                                           "inferred from where its roots sit on the source character)",
                                           json_schema_extra=UNITS_ENUM)] = "auto",
    guides: Annotated[int | None, ranged_form("guides", f"default {solver_options.DEFAULT_GUIDES}")] = None,
    k: Annotated[int, ranged_form("k")] = _DEFAULTS.k,
    anchoring: Annotated[Anchoring, Form(
        description="anchor particles to the source's bones (Eq. 2) or to its surface (default auto: the bones "
                    "when the source character has a skeleton, else the surface)")] = _DEFAULTS.anchoring,
    prim: Annotated[str | None, Form(
        description="USD or Alembic hair: read only the curves prim or object of this name or path (default: all); "
                    "other formats refuse it", min_length=1, max_length=MAX_PRIM_CHARACTERS)] = None,
    guides_from: Annotated[str | None, Form(
        description=f"take as guides the strands this per-strand attribute flags (e.g. {solver_options.GUIDE_FLAG} of an "
                    "Unreal groom) instead of selecting `guides` of them", min_length=1,
        max_length=MAX_ATTRIBUTE_NAME)] = None,
) -> HairstyleOut:
    record = await hairstyles.create_hairstyle(repository, queue, settings, owner, source_character_id, as_upload(hair),
                                               units, k, guides, anchoring, prim, guides_from)
    return hairstyles.hairstyle_out(repository, record)


@router.get("", response_model=HairstylePage, summary="The caller's hairstyles, newest first",
            responses=problem_responses(401, 422))
def list_hairstyles(owner: Owner, repository: RepositoryDep, limit: PageLimit = DEFAULT_PAGE,
                    offset: PageOffset = 0) -> HairstylePage:
    page, total = repository.list_owned(HairstyleRecord, owner, limit, offset)
    return HairstylePage(hairstyles=[hairstyles.hairstyle_out(repository, record) for record in page], total=total,
                         limit=limit, offset=offset, next_offset=offset + limit if offset + limit < total else None)


@router.get("/{hairstyle_id}", response_model=HairstyleOut, summary="A hairstyle and its preprocessing state",
            responses=problem_responses(401, 404, 422))
def get_hairstyle(repository: RepositoryDep, hairstyle: OwnedHairstyle) -> HairstyleOut:
    return hairstyles.hairstyle_out(repository, hairstyle)
