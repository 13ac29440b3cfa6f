"""Uploads: extensions, units, limits, and solver errors turned into problems naming the field."""

import io
import signal

import pytest
from starlette.datastructures import UploadFile

from hairport import solver
from hairport.service.errors import Problem
from hairport.service.uploads import check_units, died, extension_of, input_problem
from hairport.service.validation import ChildDied


def upload(name: str) -> UploadFile:
    return UploadFile(io.BytesIO(b""), filename=name)


def test_extensions_and_units():
    assert extension_of(upload("Body.OBJ"), (".obj", ".ply"), "mesh") == ".obj"
    for name in ("body.stl", "body", "", "../x/.obj.exe"):
        with pytest.raises(Problem) as refused:
            extension_of(upload(name), (".obj",), "mesh")
        assert (refused.value.status, refused.value.code) == (415, "unknown_format")
    check_units(None)
    for units in solver.UNITS:
        check_units(units)
    with pytest.raises(Problem) as refused:
        check_units("ft")
    assert (refused.value.status, refused.value.code) == (422, "bad_units")


def test_input_errors_name_the_field_not_the_file():
    too_large = input_problem(solver.InputError("60 strands above 50", "/storage/blobs/x", "too_large"), "hair")
    assert (too_large.status, too_large.code, too_large.detail) == (413, "too_large", "hair: 60 strands above 50")
    bad = input_problem(solver.InputError("cut short", "/storage/blobs/y", "truncated"), "mesh")
    assert (bad.status, bad.code) == (422, "truncated") and "/storage" not in bad.detail
    unnamed = input_problem(solver.InputError("no", code=None), "skeleton")
    assert (unnamed.status, unnamed.code, unnamed.detail) == (422, "bad_input", "skeleton: no")
    over = input_problem(solver.InputError("needs 3 GiB", None, solver.OVER_MEMORY_BUDGET), "hair")
    assert (over.status, over.code) == (413, "over_memory_budget")


def test_a_dead_validating_process_refuses_the_file_by_how_it_died():
    killed = input_problem(died(ChildDied(-signal.SIGKILL)), "hair")
    assert (killed.status, killed.code) == (413, "over_memory_budget") and killed.detail.startswith("hair: ")
    crashed = input_problem(died(ChildDied(-signal.SIGSEGV)), "mesh")
    assert (crashed.status, crashed.code) == (422, "bad_file") and "exit status -11" in crashed.detail


def test_axes_are_checked_and_normalised():
    from hairport.service.uploads import check_axis

    assert [check_axis(axis, "up_axis") for axis in (None, "auto", "z", "-X", "+y")] == [None, None, "+z", "-x", "+y"]
    with pytest.raises(Problem) as refused:
        check_axis("up", "up_axis")
    assert (refused.value.status, refused.value.code) == (422, "bad_axis") and "up_axis must be one of" in str(
        refused.value.detail)
    check_units("auto")
