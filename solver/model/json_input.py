"""Reading JSON that comes from outside (glTF, skeleton sidecars, hairline curves, artifact meta).

``json.loads`` recurses once per nesting level: a document nested 200,000 deep (a few hundred
kilobytes of brackets) raises ``RecursionError`` instead of a decoding error. Every JSON input
of hairport is read through :func:`parse_json`, the one place where that, and undecodable
bytes, become an :class:`~hairport.solver.model.errors.InputError` with a stable code.
"""

from __future__ import annotations

import json

from hairport.solver.model.errors import InputError

#: the code of a JSON document nested deeper than the parser's recursion allows
TOO_DEEP = "too_deep"


def parse_json(data: bytes | str, source: str | None, code: str, what: str = "") -> object:
    """The document of ``data`` (UTF-8 bytes or text).

    Raises
    ------
    InputError
        ``code`` for bytes that are not UTF-8 JSON; ``too_deep`` for nesting deeper than
        Python's recursion limit allows (hairport's documents nest fewer than 10 levels).
    """
    subject = f"{what} is " if what else ""
    try:
        text = data.decode("utf-8") if isinstance(data, (bytes, bytearray, memoryview)) else data
        if isinstance(text, memoryview):
            text = bytes(text).decode("utf-8")
        return json.loads(text)
    except (UnicodeDecodeError, json.JSONDecodeError) as error:
        raise InputError(f"{subject}not valid JSON ({error})", source, code) from None
    except RecursionError:
        raise InputError(f"{subject}nested too deeply to be read", source, TOO_DEEP) from None
