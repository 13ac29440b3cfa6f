"""glTF containers and buffers: the JSON document, the GLB binary chunk, accessors, node transforms.

:func:`read_gltf_container` splits a ``.glb`` into its JSON and binary chunks (a ``.gltf`` is
the JSON itself); a :class:`GltfReader` then reads accessors as numpy arrays (numpy over the
buffers, strides and normalised integers included) and the node hierarchy's transforms, with
a range check on every index and offset, so a malformed file gives an
:class:`~hairport.solver.model.errors.InputError` and never reads outside a buffer. Buffers
are the GLB chunk, ``data:`` URIs, or, only when external files are allowed (the command line's
own files), files beside the document (relative paths only). Otherwise a document any ``uri`` of
which (a buffer's, an image's, an extension's) is not a ``data:`` URI is refused, code
``external_reference`` (:func:`refuse_external_uris`): in the service's blob store the files beside
an upload are other uploads.
"""

from __future__ import annotations

import base64
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from hairport.solver.io.external import ALLOW_EXTERNAL_FILES, external_reference
from hairport.solver.model.errors import InputError
from hairport.solver.model.json_input import parse_json

#: the first four bytes of a GLB file
GLB_MAGIC = b"glTF"
#: GLB chunk types (little-endian ``b"JSON"`` and ``b"BIN\0"``)
GLB_JSON_CHUNK = 0x4E4F534A
GLB_BIN_CHUNK = 0x004E4942
#: accessor component types and element widths (glTF 2.0 specification)
COMPONENT_DTYPES = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
TYPE_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
#: the scheme of a URI that holds its bytes itself (RFC 2397) rather than naming a file
DATA_URI = "data:"


def refuse_external_uris(document: dict, source: str) -> None:
    """Refuse a document any ``uri`` of which names a file (code ``external_reference``).

    Every object member ``uri`` of the document (buffers, images, and the extensions' own) is
    looked at, however deep: a string that is not a ``data:`` URI names a file or a server.

    Parameters
    ----------
    document : dict
        The glTF JSON.
    source : str
        The file, for the error.

    Raises
    ------
    InputError
        ``external_reference``, naming the first such ``uri``, where it is, and how many more.
    """
    named = []
    stack: list = [(document, "")]
    while stack:  # a stack, not recursion: the JSON parser already bounded the nesting
        value, where = stack.pop()
        if isinstance(value, dict):
            uri = value.get("uri")
            if isinstance(uri, str) and not uri.startswith(DATA_URI):
                named.append((where or "/", uri))
            stack.extend((item, f"{where}/{key}") for key, item in reversed(value.items())
                         if isinstance(item, (dict, list)))
        else:  # a list; numbers and strings in it are no objects with a uri
            stack.extend((item, f"{where}/{index}") for index, item in reversed(list(enumerate(value)))
                         if isinstance(item, (dict, list)))
    if named:
        where, uri = named[0]
        raise external_reference(f"{where} uri", uri, source, more=len(named) - 1)


def read_gltf_container(path: Path) -> tuple[dict, bytes | None]:
    """The JSON document and the GLB binary chunk (``None`` for ``.gltf``)."""
    source = str(path)
    data = path.read_bytes()
    binary = None
    if data[:4] == GLB_MAGIC:
        if len(data) < 20:
            raise InputError("GLB file is truncated (no chunk header)", source, "truncated")
        _, version, length = np.frombuffer(data, "<u4", 3)
        if version != 2:
            raise InputError(f"GLB version {version} is not supported (expected 2)", source, "bad_mesh")
        if length > len(data):
            raise InputError(f"GLB header declares {length} bytes, file has {len(data)}", source, "truncated")
        chunks = []
        position = 12
        while position + 8 <= length:
            chunk_length, chunk_type = (int(x) for x in np.frombuffer(data, "<u4", 2, position))
            start, end = position + 8, position + 8 + chunk_length
            if end > length:
                raise InputError("GLB chunk runs past the end of the file", source, "truncated")
            chunks.append((chunk_type, data[start:end]))
            position = end + (-end % 4)
        if not chunks or chunks[0][0] != GLB_JSON_CHUNK:
            raise InputError("GLB file does not start with a JSON chunk", source, "bad_mesh")
        json_bytes = chunks[0][1]
        binary = next((chunk for kind, chunk in chunks[1:] if kind == GLB_BIN_CHUNK), None)
    else:
        json_bytes = data
    document = parse_json(json_bytes, source, "bad_mesh", "glTF JSON")
    if not isinstance(document, dict):
        raise InputError("glTF JSON is not an object", source, "bad_mesh")
    return document, binary


class GltfReader:
    """Accessors, buffers and node transforms of a glTF document, with range checks."""

    def __init__(self, document: dict, binary: bytes | None, path: Path,
                 allow_external_files: bool = ALLOW_EXTERNAL_FILES):
        self.document = document
        self.binary = binary
        self.path = path
        self.allow_external_files = allow_external_files
        self.source = str(path)
        self._buffers: dict[int, bytes] = {}

    def _error(self, problem: str, code: str = "bad_mesh") -> InputError:
        return InputError(problem, self.source, code)

    def item(self, kind: str, index) -> dict:
        """``document[kind][index]``, checked to exist and to be an object."""
        items = self.document.get(kind, [])
        if not isinstance(index, int) or not 0 <= index < len(items) or not isinstance(items[index], dict):
            raise self._error(f"glTF refers to {kind}[{index}], which does not exist")
        return items[index]

    def buffer(self, index: int) -> bytes:
        """The bytes of buffer ``index``: the GLB binary chunk, a ``data:`` URI, or a file beside the document
        (only when external files are allowed; else ``external_reference``)."""
        if index in self._buffers:
            return self._buffers[index]
        buffer = self.item("buffers", index)
        uri = buffer.get("uri")
        if uri is None:
            if self.binary is None:
                raise self._error(f"buffer {index} has no uri and the file has no binary chunk")
            data = self.binary
        elif uri.startswith(DATA_URI):
            try:
                data = base64.b64decode(uri.split(",", 1)[1], validate=False)
            except (IndexError, ValueError):
                raise self._error(f"buffer {index} has a malformed data uri") from None
        elif not self.allow_external_files:
            raise external_reference(f"buffer {index} uri", uri, self.source)
        else:
            relative = Path(unquote(uri))
            if relative.is_absolute() or ".." in relative.parts or ":" in uri.split("/", 1)[0]:
                raise self._error(f"buffer {index} uri {uri!r} must be a relative path beside the file")
            target = self.path.parent / relative
            if not target.is_file():
                raise self._error(f"buffer {index} file {uri!r} not found", "not_found")
            data = target.read_bytes()
        declared = buffer.get("byteLength", len(data))
        if not isinstance(declared, int) or declared > len(data):
            raise self._error(f"buffer {index} declares {declared} bytes but holds {len(data)}", "truncated")
        self._buffers[index] = data
        return data

    def count(self, index, what: str) -> int:
        """The element count of accessor ``index`` (``what`` names it in the error when it is missing)."""
        if index is None:
            raise self._error(f"a primitive has no {what} accessor")
        count = self.item("accessors", index).get("count", 0)
        if not isinstance(count, int) or count < 0:
            raise self._error(f"accessor {index} has a bad count {count!r}")
        return count

    def accessor(self, index: int) -> np.ndarray:
        """Accessor ``index`` as a ``(count, width)`` array (normalised integers as float64)."""
        accessor = self.item("accessors", index)
        if "sparse" in accessor:
            raise self._error(f"accessor {index} is sparse; sparse accessors are not supported")
        dtype = COMPONENT_DTYPES.get(accessor.get("componentType"))
        width = TYPE_WIDTHS.get(accessor.get("type"))
        count = self.count(index, "")
        if dtype is None or width is None:
            raise self._error(f"accessor {index} has an unknown component type or type")
        dtype = np.dtype(dtype).newbyteorder("<")
        if "bufferView" not in accessor:
            values = np.zeros((count, width), dtype=dtype)
        else:
            view = self.item("bufferViews", accessor["bufferView"])
            data = self.buffer(view.get("buffer", -1))
            view_offset = view.get("byteOffset", 0)
            view_length = view.get("byteLength", 0)
            offset = view_offset + accessor.get("byteOffset", 0)
            element = dtype.itemsize * width
            stride = view.get("byteStride", element)
            if stride < element or view_offset + view_length > len(data):
                raise self._error(f"accessor {index}: bufferView stride or length is invalid", "truncated")
            end = offset + (count - 1) * stride + element if count else offset
            if offset < view_offset or end > view_offset + view_length:
                raise self._error(f"accessor {index} runs past the end of its bufferView", "truncated")
            if offset % dtype.itemsize or stride % dtype.itemsize:
                raw = np.frombuffer(data, np.uint8, end - offset, offset)
                values = np.lib.stride_tricks.as_strided(raw, (count, element), (stride, 1)).copy()
                values = values.view(dtype).reshape(count, width)
            else:
                values = np.ndarray((count, width), dtype, data, offset, (stride, dtype.itemsize)).copy()
        if accessor.get("normalized") and dtype.kind in "iu":
            values = np.maximum(values / float(np.iinfo(dtype).max), -1.0)
        return values

    def local_matrix(self, node: dict) -> np.ndarray:
        """(4, 4) transform of a node: its ``matrix``, else translation @ rotation (quaternion) @ scale."""
        if "matrix" in node:
            matrix = np.asarray(node["matrix"], dtype=np.float64)
            if matrix.shape != (16,):
                raise self._error("a node matrix does not have 16 numbers")
            return matrix.reshape(4, 4).T  # column-major
        translation = np.asarray(node.get("translation", [0, 0, 0]), dtype=np.float64)
        x, y, z, w = np.asarray(node.get("rotation", [0, 0, 0, 1]), dtype=np.float64)
        scale = np.asarray(node.get("scale", [1, 1, 1]), dtype=np.float64)
        norm = np.sqrt(x * x + y * y + z * z + w * w) or 1.0
        x, y, z, w = x / norm, y / norm, z / norm, w / norm
        rotation = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
            ]
        )
        matrix = np.eye(4)
        matrix[:3, :3] = rotation * scale[None, :]
        matrix[:3, 3] = translation
        return matrix

    def parents(self) -> np.ndarray:
        """(N,) int64 parent node of every node, -1 for a root; a node with two parents is an error."""
        nodes = self.document.get("nodes", [])
        parents = np.full(len(nodes), -1, dtype=np.int64)
        for i, node in enumerate(nodes):
            for child in node.get("children", []):
                if not isinstance(child, int) or not 0 <= child < len(nodes) or parents[child] >= 0:
                    raise self._error(f"node {i} has an invalid or shared child {child!r}")
                parents[child] = i
        return parents

    def world_matrices(self) -> np.ndarray:
        """(N, 4, 4) world transform of every node."""
        nodes = self.document.get("nodes", [])
        parents = self.parents()
        local = np.stack([self.local_matrix(n) for n in nodes]) if nodes else np.zeros((0, 4, 4))
        world = local.copy()
        done = parents < 0
        for _ in range(len(nodes)):
            if done.all():
                break
            ready = ~done & done[np.maximum(parents, 0)]
            index = np.flatnonzero(ready)
            world[index] = world[parents[index]] @ local[index]
            done[index] = True
        if not done.all():
            raise self._error("glTF node hierarchy has a cycle")
        return world
