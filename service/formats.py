"""The format of an upload whose file name has no extension, from its first bytes.

Clients that stream a file without a name (``curl -F mesh=@-``, browser blobs, generated
clients) still name its format by its content. A name with an extension wins: ``body.stl`` is
refused even if it holds OBJ text. ``.data`` hair has no signature, so it needs its name."""

from __future__ import annotations

#: bytes read from the start of an upload to recognise it
SNIFF_BYTES = 512
#: signatures at the very start of a file, and the extension they stand for
SIGNATURES: tuple[tuple[bytes, str], ...] = (
    (b"ply\n", ".ply"), (b"ply\r\n", ".ply"),  # PLY, ASCII or binary
    (b"glTF", ".glb"),  # binary glTF
    (b"PK\x03\x04", ".npz"),  # a zip archive: numpy's .npz
    (b"HAIR", ".hair"),  # Cem Yuksel's HAIR
    (b"PXR-USDC", ".usdc"),  # USD crate
    (b"#usda ", ".usda"),  # USD text (before OBJ: both start with '#')
    (b"Ogawa", ".abc"),  # Alembic's Ogawa archive
)
#: a byte-order mark and white space a text file may start with
TEXT_LEAD = b"\xef\xbb\xbf \t\r\n"
#: statements an OBJ file (mesh or polyline hair) starts with
OBJ_STATEMENTS = frozenset({b"#", b"v", b"vn", b"vt", b"vp", b"f", b"l", b"o", b"g", b"s", b"mtllib", b"usemtl"})
#: what JSON content is taken as, by the extensions a field accepts
JSON_SUFFIXES = (".gltf", ".json")


def sniffed_suffix(head: bytes, allowed: tuple[str, ...]) -> str | None:
    """The extension among ``allowed`` that the file starting with ``head`` is, or ``None``."""
    for signature, suffix in SIGNATURES:
        if head.startswith(signature):
            return suffix if suffix in allowed else None
    if b"\x00" in head:
        return None
    text = head.lstrip(TEXT_LEAD)
    if text.startswith((b"{", b"[")):
        return next((suffix for suffix in JSON_SUFFIXES if suffix in allowed), None)
    words = text.split(None, 1)
    if words and (words[0] in OBJ_STATEMENTS or words[0].startswith(b"#")) and ".obj" in allowed:
        return ".obj"
    return None
