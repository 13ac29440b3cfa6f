"""Parsing a file with a foreign library (USD, Alembic) in a child process with bounded memory and time.

Those libraries decode damaged or hostile files in C++, where a few kilobytes can make them
allocate gigabytes (a mutated 2 KB crate file took 5 GB and 6 s here) or crash. The child
(``python -m hairport.solver.io.sandbox PARSER FUNCTION ...``) runs a parser module's
function returning a dict of arrays (:mod:`~hairport.solver.io.hair.sandboxed` for the hair
readers, a character reader's ``mesh_arrays``) under a heap limit (:data:`CHILD_BASE_BYTES` plus
:data:`CHILD_BYTES_PER_FILE_BYTE` per byte of the file) and a time limit
(:data:`CHILD_SECONDS`), and hands back the arrays in an ``.npz``; its input errors come back
as JSON and are raised here. This process never holds more than the arrays handed back.
"""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

from hairport.solver.model.errors import InputError

#: the heap limit is this much for Python and the library themselves ...
CHILD_BASE_BYTES = 768 * 2**20
#: ... plus this many times the file's size (a file's arrays expand a few times at most: floats
#: are stored raw, only integer arrays are compressed), at least CHILD_MIN_DATA_BYTES
CHILD_BYTES_PER_FILE_BYTE = 100
CHILD_MIN_DATA_BYTES = 256 * 2**20
#: seconds a child may parse before it is stopped (code ``too_large``)
CHILD_SECONDS = 60
#: the child's exit status when it reports an input error (its code and message on stdout, JSON)
CHILD_INPUT_ERROR = 3
#: the parsers a child may import (a module path from the command line is never imported blindly)
PARSERS = ("hairport.solver.io.hair.sandboxed", "hairport.solver.io.character.usd", "hairport.solver.io.character.alembic")
#: the functions a child may call: a hair parser's strands, a character parser's mesh
FUNCTIONS = ("strands_arrays", "mesh_arrays", "mesh_frames")


def run_in_child(parser: str, function: str, source: str, size: int, arguments: dict, name: str,
                 library: str) -> dict[str, np.ndarray]:
    """``parser.function(source, **arguments)`` run in a child under the limits (module notes).

    Parameters
    ----------
    parser : str
        One of :data:`PARSERS`.
    function : str
        A function of it returning a dict of arrays (an :class:`InputError` for bad input).
    source : str
        The file.
    size : int
        Its size in bytes (sets the heap limit).
    arguments : dict
        JSON-able keyword arguments.
    name : str
        The file's name for messages (an upload's, not the scratch file's).
    library : str
        The library's name, for messages ("USD").

    Returns
    -------
    arrays : dict of str to ndarray

    Raises
    ------
    InputError
        The child's input error; ``too_large`` when it ran out of memory or time.
    """
    heap = CHILD_BASE_BYTES + max(CHILD_MIN_DATA_BYTES, CHILD_BYTES_PER_FILE_BYTE * size)
    with tempfile.TemporaryDirectory(prefix="hairport-sandbox-") as folder:
        result = os.path.join(folder, "result.npz")
        command = [sys.executable, "-m", __name__, parser, function, source, result, json.dumps(arguments), str(heap)]
        try:
            child = subprocess.run(command, capture_output=True, timeout=CHILD_SECONDS, check=False)
        except subprocess.TimeoutExpired:
            raise InputError(f"{library} took more than {CHILD_SECONDS} s to read the file: refused", name,
                             "too_large") from None
        if child.returncode == CHILD_INPUT_ERROR:
            problem = json.loads(child.stdout)
            raise InputError(problem["message"], name, problem["code"])
        if child.returncode != 0:
            raise InputError(f"{library} could not read the file within {heap // 2**20} MB (a damaged or hostile "
                             f"file; exit status {child.returncode})", name, "too_large")
        with np.load(result, allow_pickle=False) as arrays:
            return {name: arrays[name] for name in arrays.files}


def _child_main(argv: list[str]) -> int:
    """``python -m hairport.solver.io.sandbox PARSER FUNCTION SOURCE RESULT ARGUMENTS_JSON HEAP``."""
    import resource

    parser, function, source, result, arguments, heap = argv
    resource.setrlimit(resource.RLIMIT_DATA, (int(heap), int(heap)))
    if parser not in PARSERS or function not in FUNCTIONS:
        raise SystemExit(f"unknown parser {parser!r} or function {function!r}")
    try:
        arrays = getattr(importlib.import_module(parser), function)(source, **json.loads(arguments))
    except InputError as error:
        sys.stdout.write(json.dumps({"code": error.code, "message": error.problem}))
        return CHILD_INPUT_ERROR
    np.savez(result, **arrays)
    return 0


if __name__ == "__main__":
    sys.exit(_child_main(sys.argv[1:]))
