"""What a validating process runs: the solver's own readers and fit check on an upload stored on disk.

The API's validation pool (:mod:`hairport.service.validation`) starts
``python -m hairport.service.validation_child BUDGET_BYTES`` a few times. Each child lowers its
scheduling priority (:data:`NICENESS`), imports the solver and runs the validation once on a tiny
built-in body (:func:`prewarm`: the readers' and the distance queries' code loaded, compiled kernels
fetched from numba's cache, the BLAS buffers allocated), then limits its heap (``RLIMIT_DATA``) to
what it holds then plus ``BUDGET_BYTES`` and answers one request at a time:

* a request is one JSON line on stdin, ``{"check": "hair" | "character", "arguments": {...}}``:
  paths of stored files and small options, never arrays;
* the child says it took the request (``{"taken": true}``), then answers with one JSON line on the
  protocol stream (the child's original stdout; anything else a library prints goes to stderr):
  ``{"result": {...}}`` (counts, units, bone names),
  ``{"error": {"field", "code", "problem"}}`` for refused input (``over_memory_budget`` when the
  check ran out of its heap), ``{"crash": traceback}`` for a defect. ``"retiring": true`` says
  that the child exits after this answer (it ran out of its heap, or its heap grew: the pool starts
  a fresh one, with the whole budget).

This module imports the solver's public face only: no web framework in the validating processes.
"""

from __future__ import annotations

import contextlib
import json
import os
import resource
import signal
import sys
import traceback
import warnings

import numpy as np

from hairport import solver

#: a child whose data segment grew this much beyond its start-up size over its validations
#: (fragments of the allocator's heap) retires after its answer: its limit is fixed at start-up,
#: so growth would shrink the budget of the next validations
RETIRE_GROWTH_BYTES = 128 * 2**20
#: the first line a child writes when it is ready for requests, and the line it writes when it has
#: read one (a request it never took can be sent to another child)
READY, TAKEN = "ready", "taken"
#: side of the matrices whose product makes the BLAS library allocate its buffers at start-up
BLAS_WARM_SIZE = 256
#: scheduling niceness of a validating process: on cores it shares with the API's event loop, the
#: requests (polls of a few ms) are served first and a validation (seconds) takes what is left
NICENESS = 10


class FieldError(Exception):
    """A refused input and the request field it came from."""

    def __init__(self, field: str, code: str, problem: str):
        super().__init__(problem)
        self.field, self.code, self.problem = field, code, problem


class OverBudget(Exception):
    """The check ran out of the heap one validation may use."""


def out_of_memory(error: BaseException) -> bool:
    """Whether ``error`` was raised while handling a :class:`MemoryError` (a reader that turns any failure
    of its parsing library into a refusal of the file also turns running out of the budget into one)."""
    seen = set()
    while error is not None and id(error) not in seen:
        if isinstance(error, MemoryError):
            return True
        seen.add(id(error))
        error = error.__cause__ or error.__context__
    return False


@contextlib.contextmanager
def in_field(field: str):
    """Refusals (:class:`~hairport.solver.InputError`) raised inside the block are ``field``'s."""
    try:
        yield
    except solver.InputError as error:
        if out_of_memory(error):
            raise OverBudget() from None
        raise FieldError(field, error.code or "bad_input", error.problem) from None


def check_character(mesh: str, skeleton: str | None, units: str | None, max_vertices: int, max_faces: int,
                    max_bytes: int) -> dict:
    """Read an uploaded character (:func:`hairport.solver.read_character`); what its record keeps.

    Returns
    -------
    result : dict
        ``units`` (stated by its files, or None), ``vertices``, ``faces``, ``bones`` (names).
    """
    with in_field("mesh"):
        character, stated = solver.read_character(mesh, skeleton_path=skeleton, units=units,
                                                  max_vertices=max_vertices, max_faces=max_faces, max_bytes=max_bytes)
    return {"units": stated, "vertices": int(character.n_vertices), "faces": int(character.n_faces),
            "bones": list(character.skeleton.names) if character.skeleton is not None else []}


def check_hair(hair: str, units: str, prim: str | None, limits: dict, source: dict | None,
               guides_from: str | None, max_guides: int) -> dict:
    """Read an uploaded hair file as the solver will, refuse it unless it sits on its source character,
    and check its guide flags.

    Parameters
    ----------
    hair : str
        The stored file.
    units : str
        Given, or ``auto`` (the units the file records, else inferred from where it sits).
    prim : str or None
        USD or Alembic: the curves to read.
    limits : dict
        :class:`~hairport.solver.ReadLimits` fields.
    source : dict or None
        The source character's ``mesh`` and ``skeleton`` paths, ``units``, ``up``, ``front`` and its
        ``max_vertices``, ``max_faces``, ``max_bytes``; None when its files are gone (the fit is then
        left to the preprocessing, which reports it).
    guides_from : str or None
        A per-strand attribute flagging the guides.
    max_guides : int

    Returns
    -------
    result : dict
        ``units`` (given or recorded, None when inferred), ``strands``, ``particles``.
    """
    with in_field("hair"):
        stated = units if units != solver.AUTO else solver.recorded_hair_units(hair)
        loaded = solver.read_hair(hair, units=stated or "m", prim=prim, limits=solver.ReadLimits(**limits))
        if source is not None:
            body, body_units = solver.read_character(
                source["mesh"], skeleton_path=source["skeleton"], units=source["units"],
                max_vertices=source["max_vertices"], max_faces=source["max_faces"], max_bytes=source["max_bytes"])
            solver.canonical_source(body, loaded, source_units=body_units, hair_units=stated, up=source["up"],
                                    front=source["front"], measure=False)
    if guides_from is not None:
        with in_field("guides_from"):
            solver.flagged_guides(loaded, guides_from, max_guides)
    return {"units": stated, "strands": int(loaded.n_strands), "particles": int(loaded.n_particles)}


#: the checks a request may name
CHECKS = {"hair": check_hair, "character": check_character}


def prewarm() -> None:
    """Run what a validation runs (readers, the body queries and their compiled kernels) on a tiny
    box with a few strands on its top, so that the first upload does not pay for it."""
    # the BLAS library allocates its work buffer on its first product and exits the process when it
    # cannot (under the heap limit): allocated now, before the limit
    square = np.ones((BLAS_WARM_SIZE, BLAS_WARM_SIZE))
    square @ square
    np.linalg.svd(square[:, :3])
    corners = np.array([[x, y, z] for x in (-0.08, 0.08) for y in (1.5, 1.7) for z in (-0.09, 0.09)])
    faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                      [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
    roots = np.array([[-0.05, 1.7, -0.05], [0.05, 1.7, -0.05], [0.05, 1.7, 0.05], [-0.05, 1.7, 0.05]])
    points = np.stack([roots, roots + [0.0, 0.05, 0.0]], axis=1).reshape(-1, 3)
    hair = solver.Hair(points, np.arange(0, len(points) + 1, 2))
    with contextlib.suppress(solver.InputError), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        solver.canonical_source(solver.Character(corners, faces, name="prewarm"), hair, source_units="m",
                                measure=False)


def data_bytes() -> int:
    """This process's data segment (``VmData``: what ``RLIMIT_DATA`` limits), in bytes."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmData:"):
                return int(line.split()[1]) * 1024
    raise RuntimeError("no VmData in /proc/self/status")


def limit_heap(budget_bytes: int) -> int:
    """Limit the data segment to its size now plus ``budget_bytes``; the limit.

    Only the soft limit: a sandboxed parser's child (:mod:`hairport.solver.io.sandbox`) sets its own."""
    limit = data_bytes() + budget_bytes
    _, hard = resource.getrlimit(resource.RLIMIT_DATA)
    resource.setrlimit(resource.RLIMIT_DATA, (limit if hard == resource.RLIM_INFINITY else min(limit, hard), hard))
    return limit


def answer_to(request: dict, budget_bytes: int) -> dict:
    """Run one request; its answer (module notes)."""
    error = None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a reader's notes (short strands skipped) are not the API's
            return {"result": CHECKS[request["check"]](**request["arguments"])}
    except FieldError as refused:
        error = {"field": refused.field, "code": refused.code, "problem": refused.problem}
    except (MemoryError, OverBudget):
        # the arrays of the failed check are freed when this block is left: the answer is built after it
        error = {"field": request.get("field"), "code": solver.OVER_MEMORY_BUDGET,
                 "problem": f"validating the file needs more than the {budget_bytes / 2**20:,.0f} MB of memory one "
                            "validation may use in this deployment (HAIRPORT_VALIDATION_MEMORY_BYTES)"}
    except Exception:  # noqa: BLE001 - a defect: reported to the API, which answers 500 and logs it
        return {"crash": traceback.format_exc()}
    return {"error": error}


def main(argv: list[str]) -> int:
    """``python -m hairport.service.validation_child BUDGET_BYTES`` (module notes)."""
    budget_bytes = int(argv[0])
    protocol = os.fdopen(os.dup(sys.stdout.fileno()), "w", buffering=1)
    os.dup2(sys.stderr.fileno(), sys.stdout.fileno())  # what libraries print must not mix with the answers
    # Ctrl-C in the server's terminal reaches its whole process group: the server stops its children itself
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    os.nice(NICENESS)
    prewarm()
    limit = limit_heap(budget_bytes)
    protocol.write(json.dumps({READY: True, "pid": os.getpid()}) + "\n")
    for line in sys.stdin:  # ends when the pool closes our stdin, or when the API process is gone
        protocol.write(json.dumps({TAKEN: True}) + "\n")
        answer = answer_to(json.loads(line), budget_bytes)
        # a check that ran out of the heap leaves it fragmented, and the BLAS library exits when it
        # cannot allocate: the next validation gets a fresh process and the whole budget
        answer["retiring"] = (answer.get("error", {}).get("code") == solver.OVER_MEMORY_BUDGET
                              or data_bytes() > limit - budget_bytes + RETIRE_GROWTH_BYTES)
        protocol.write(json.dumps(answer) + "\n")
        if answer["retiring"]:
            break
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
