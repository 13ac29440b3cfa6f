"""Streaming uploads into the storage, and validation of what they hold through the solver's readers
(in the validation pool's processes, :mod:`.validation`)."""

from __future__ import annotations

import io
from pathlib import PurePosixPath

from fastapi import UploadFile

from hairport import solver
from hairport.settings import Settings
from hairport.storage import LocalStorage, UploadTooLarge, iter_upload

from .errors import Problem
from .formats import SNIFF_BYTES, sniffed_suffix
from .schemas import AXIS_FORM_CHOICES, UNITS_CHOICES
from .validation import BUSY_RETRY_SECONDS, ChildDied, ValidationBusy, ValidationTimeout, shared_pool

#: what a file field takes: a file part, or a part without a file name (``curl -F 'mesh=<body.obj'``),
#: which the form parser hands over as text; both are the file's content (the contract shows a file)
FilePart = UploadFile | str


def as_upload(part: FilePart | None) -> UploadFile | None:
    """The upload of a file field, whichever way it was sent (a text part has no name: its format is
    recognised by its content)."""
    if isinstance(part, str):
        return UploadFile(io.BytesIO(part.encode()))
    return part


def extension_of(upload: UploadFile, allowed: tuple[str, ...], field: str) -> str:
    """The lower-case extension of the upload's file name, if allowed; for a name without one, the
    extension its content shows (the name is used for nothing else). 415 ``unknown_format`` otherwise."""
    suffix = PurePosixPath(upload.filename or "").suffix.lower()
    if suffix in allowed:
        return suffix
    if not suffix:
        head = upload.file.read(SNIFF_BYTES)
        upload.file.seek(0)
        sniffed = sniffed_suffix(head, allowed)
        if sniffed is not None:
            return sniffed
        raise Problem(415, "unknown_format", f"{field}: the file name has no extension and the content is none of "
                                             f"{', '.join(allowed)}: name the file with its extension")
    raise Problem(415, "unknown_format", f"{field}: file name must end in one of {', '.join(allowed)} (got {suffix!r})")


async def store_upload(storage: LocalStorage, upload: UploadFile, settings: Settings, suffix: str, field: str):
    """Stream an upload into the blob store; 413 above ``max_upload_bytes``."""
    try:
        return await storage.save_stream(iter_upload(upload), settings.max_upload_bytes, suffix)
    except UploadTooLarge as error:
        raise Problem(413, "upload_too_large",
                      f"{field}: upload larger than the limit of {error.limit:,} bytes") from None


#: input codes answered 413: above a configured limit or the memory budget (the input is too
#: big for this deployment, not malformed)
OVERSIZE_CODES = ("too_large", solver.OVER_MEMORY_BUDGET)


#: the code of a format whose optional library this deployment lacks
UNAVAILABLE_FORMAT = "format_unavailable"


def input_problem(error: solver.InputError, field: str) -> Problem:
    """413 for inputs above the configured limits, 415 for a format this deployment cannot read (Alembic
    without its optional bindings), 422 for every other bad input.

    The detail names the request field, never a storage path."""
    status = 413 if error.code in OVERSIZE_CODES else 415 if error.code == UNAVAILABLE_FORMAT else 422
    return Problem(status, error.code or "bad_input", f"{field}: {error.problem}")


async def validated(settings: Settings, check: str, field: str, **arguments) -> dict:
    """Run a validation (``hair`` or ``character``: :mod:`.validation_child`) in the validation pool; its
    result. Refused input becomes a problem naming its field, and so do a validation over the memory budget
    (413 ``over_memory_budget``, also when the kernel killed its process), over the time limit (413
    ``too_large``) or crashing its process (422 ``bad_file``); a pool busy for longer than
    ``validation_wait_seconds`` is 503 ``validation_busy``."""
    try:
        answer = await shared_pool(settings).run(check, field, arguments, settings.validation_wait_seconds,
                                                 settings.validation_timeout_seconds)
    except ValidationBusy:
        raise Problem(503, "validation_busy", f"every upload validation process stayed busy for "
                                              f"{settings.validation_wait_seconds:g} s; nothing was kept, try "
                                              f"again in {BUSY_RETRY_SECONDS} s",
                      headers={"Retry-After": str(BUSY_RETRY_SECONDS)}) from None
    except ValidationTimeout as error:
        raise input_problem(solver.InputError(
            f"validating the file took more than {error.seconds:g} s, this deployment's limit "
            "(HAIRPORT_VALIDATION_TIMEOUT_SECONDS)", None, "too_large"), field) from None
    except ChildDied as error:
        raise input_problem(died(error), field) from None
    if "crash" in answer:  # a defect, not the input's fault: 500 and the child's traceback in the log
        raise RuntimeError(f"the validation of {field} failed:\n{answer['crash']}")
    if "error" in answer:
        refused = answer["error"]
        raise input_problem(solver.InputError(refused["problem"], None, refused["code"]), refused["field"] or field)
    return answer["result"]


def died(error: ChildDied) -> solver.InputError:
    """The refusal of a file whose validating process died: killed (on a host short of memory, by the
    kernel's OOM killer) is over the memory budget, any other death a file its reader cannot take."""
    if error.killed:
        return solver.InputError("the process validating the file was killed, out of memory", None,
                                 solver.OVER_MEMORY_BUDGET)
    return solver.InputError(f"the file stopped the process validating it (exit status {error.returncode})",
                             None, "bad_file")


def check_units(units: str | None) -> None:
    """422 ``bad_units`` for units the readers do not know (``None`` or ``auto``: the file's, else inferred)."""
    if units is not None and units not in UNITS_CHOICES:
        raise Problem(422, "bad_units", f"units must be one of {', '.join(UNITS_CHOICES)}")


def check_axis(axis: str | None, field: str) -> str | None:
    """422 ``bad_axis`` for an axis that is not one of ``auto``, ``x``, ``-z``, ...; the normalised axis
    (``None`` for ``auto``)."""
    if axis is None or axis == solver.AUTO:
        return None
    try:
        return solver.parse_axis(axis)
    except solver.InputError:
        raise Problem(422, "bad_axis",
                      f"{field} must be one of {', '.join(AXIS_FORM_CHOICES)}") from None
