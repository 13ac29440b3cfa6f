"""The format of an upload without an extension, from its first bytes."""

import pytest

from hairport import solver
from hairport.service.formats import sniffed_suffix

MESH = solver.MESH_EXTENSIONS
HAIR = tuple(f".{name}" for name in solver.HAIR_FORMATS)


@pytest.mark.parametrize("head, allowed, suffix", [
    (b"ply\nformat binary_little_endian 1.0\n", MESH, ".ply"),
    (b"ply\r\nformat ascii 1.0\r\n", HAIR, ".ply"),
    (b"glTF\x02\x00\x00\x00", MESH, ".glb"),
    (b'\xef\xbb\xbf  {"asset": {"version": "2.0"}}', MESH, ".gltf"),
    (b'{"bones": []}', (".json",), ".json"),
    (b"# exported\nv 0 0 0\n", MESH, ".obj"),
    (b"v 0 0 0\nv 0 1 0\nl 1 2\n", HAIR, ".obj"),
    (b"mtllib body.mtl\n", MESH, ".obj"),
    (b"PK\x03\x04\x14\x00", HAIR, ".npz"),
    (b"HAIR\x02\x00\x00\x00", HAIR, ".hair"),
    (b"PXR-USDC\x00\x00\x08\x00", HAIR, ".usdc"),
    (b"#usda 1.0\n(\n", HAIR, ".usda"),
    (b"Ogawa\xff\x00\x01x\n", HAIR, ".abc"),
    # not the field's formats, or nothing known
    (b"PK\x03\x04\x14\x00", MESH, None),
    (b"glTF\x02\x00\x00\x00", HAIR, None),
    (b'{"asset": {}}', HAIR, None),
    (b"\x14\x00\x00\x00\x06\x00", HAIR, None),  # .data: a count, no signature
    (b"v 0 0 0\x00\x00", MESH, None),  # NUL bytes: not text
    (b"solid cube\nfacet normal 0 0 1\n", MESH, None),  # ASCII STL
    (b"", MESH, None),
])
def test_signatures(head, allowed, suffix):
    assert sniffed_suffix(head, allowed) == suffix
