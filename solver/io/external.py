"""Files that name other files: whether a read may open them, and the refusal when it may not.

A USD layer can name other files (sublayers, references, payloads, value clips, asset-valued
attributes and metadata), a glTF document its buffers and images. Opened on a server, such a name
reads whatever the server can read (``subLayers = [@/srv/other-user/groom.usda@]`` hands that file's
strands to whoever uploaded the name), and in the service's blob store the files "beside" an upload
are other users' uploads. So a read resolves nothing outside the file it was given unless it is
told it may: :data:`ALLOW_EXTERNAL_FILES` is the one default of that option
(``ReadLimits.allow_external_files`` for hair, ``allow_external_files=`` of
:func:`~hairport.solver.io.character.load.read_character`), and only the command line, which reads
the user's own files, passes True. A refused file is an
:class:`~hairport.solver.model.errors.InputError` with code :data:`EXTERNAL_REFERENCE` naming the
kind of link and the name it holds (:func:`external_reference`), raised before anything it names
is opened.

What a format can name, and what each reader does with it by default:

- USD (``.usd``, ``.usda``, ``.usdc``): the root layer is opened alone and walked before any
  composition (:mod:`~hairport.solver.io.usd.assets`); any asset path refuses the file.
- glTF (``.gltf``, ``.glb``): every buffer and image ``uri`` other than a ``data:`` URI refuses the file.
- OBJ: ``mtllib`` is never opened (both readers read ``v``/``f``/``l`` lines only).
- PLY: trimesh is asked to skip materials, so a ``comment TextureFile`` is never opened; the hair
  PLY reader parses the bytes it was given.
- ``.hair``, ``.data``, ``.npz``, skeleton JSON: nothing in them names a file.
- Alembic: an archive names no other file (layered archives are an API of several paths, and the
  reader opens the one ``IArchive`` it is given).
"""

from __future__ import annotations

import re

from hairport.solver.model.errors import InputError

#: the code of a file that names another file a read may not open
EXTERNAL_REFERENCE = "external_reference"
#: the default of every reader's ``allow_external_files``: False, the one an upload needs (the
#: service and the worker never change it; the command line sets True for the user's own files)
ALLOW_EXTERNAL_FILES = False
#: characters of a name from the file quoted in a message: enough to recognise a path, short enough
#: that the API's problem detail (300 characters) holds the whole sentence
MAX_QUOTED_CHARS = 60
#: what a refused file should become, in the words of the message
SELF_CONTAINED = "an upload must be self-contained (flatten the stage; embed glTF buffers as data: URIs)"
# anything that is not printable on one line: control characters, line and paragraph separators
_UNPRINTABLE = re.compile(r"[\x00-\x1f\x7f-\x9f\u2028\u2029\u202a-\u202e\u2066-\u2069]")


def quoted(text: object, limit: int = MAX_QUOTED_CHARS) -> str:
    """``text`` from a file, quoted for a message: one printable line of at most ``limit`` characters."""
    text = _UNPRINTABLE.sub("?", str(text)[: 4 * limit])
    if len(text) > limit:
        text = text[: limit - 1] + "\u2026"
    return f"'{text}'"


def external_reference(kind: str, name: object, source: str | None, where: str = "", more: int = 0) -> InputError:
    """The refusal of a file that names another one.

    Parameters
    ----------
    kind : str
        The kind of link (``"sublayer"``, ``"reference"``, ``"buffer 0 uri"``...).
    name : object
        The name it holds (an asset path, a URI), quoted sanitised and bounded.
    source : str or None
        The file refused.
    where : str
        Where in the file (a prim path), quoted like ``name``.
    more : int
        How many other names the file holds.

    Returns
    -------
    error : InputError
        Code :data:`EXTERNAL_REFERENCE`.
    """
    place = f" at {quoted(where)}" if where else ""
    others = f" (and {more:,} more)" if more else ""
    return InputError(f"names a file outside itself, which is not opened: {kind} {quoted(name)}{place}{others}; "
                      f"{SELF_CONTAINED}", source, EXTERNAL_REFERENCE)
