"""Malformed inputs of every kind hairport reads: (name, extension, bytes) per case.

Truncated files of every format, empty files, garbage and NUL bytes, JSON nested 200,000 deep,
indices past int64, NaN and infinite coordinates, counts that lie, decompression bombs, and a
strand of millions of identical points. Garbage is seeded: the cases are the same every run.
"""

import io
import json
import random
import struct
import zipfile

import numpy as np

_RANDOM = random.Random(12)


def _garbage(n: int) -> bytes:
    return bytes(_RANDOM.getrandbits(8) for _ in range(n))

DEEP = 200_000

def deep_json(depth=DEEP):
    return b"[" * depth + b"]" * depth

def npz_bytes(arrays, compress=True):
    buf = io.BytesIO()
    (np.savez_compressed if compress else np.savez)(buf, **arrays)
    return buf.getvalue()

def npz_member_bomb(n_points):
    """A hairport npz whose points member is n_points zeros, deflated (a bomb)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for name, arr in (("format", np.array("hairport-hair")), ("version", np.array(1)), ("units", np.array("m")),
                          ("offsets", np.array([0, n_points], dtype=np.int64))):
            b = io.BytesIO()
            np.lib.format.write_array(b, arr)
            z.writestr(name + ".npy", b.getvalue())
        with z.open("points.npy", "w", force_zip64=True) as f:
            np.lib.format.write_array_header_1_0(f, {"descr": "<f8", "fortran_order": False, "shape": (n_points, 3)})
            chunk = bytes(1 << 20)
            left = n_points * 24
            while left > 0:
                f.write(chunk[: min(left, len(chunk))])
                left -= len(chunk)
    return buf.getvalue()

def hair_cases(ok: dict) -> list[tuple[str, str, bytes]]:
    """(name, extension, bytes)"""
    cases = []
    for ext, data in ok.items():
        cases += [(f"{ext}-empty", ext, b""), (f"{ext}-garbage", ext, _garbage(997)),
                  (f"{ext}-half", ext, data[: len(data) // 2]), (f"{ext}-head", ext, data[:7]),
                  (f"{ext}-nul", ext, b"\0" * 4096), (f"{ext}-deepjson", ext, deep_json())]
    d = ok["data"]
    cases += [("data-count-max", "data", struct.pack("<I", 0xFFFFFFFF) + d[4:]),
              ("data-neg-strand", "data", d[:4] + struct.pack("<i", -5) + d[8:])]
    nan = bytearray(d)
    nan[8:12] = struct.pack("<f", float("nan"))
    cases.append(("data-nan", "data", bytes(nan)))
    inf = bytearray(d)
    inf[8:12] = struct.pack("<f", float("inf"))
    cases.append(("data-inf", "data", bytes(inf)))
    h = ok["hair"]
    cases += [("hair-count-max", "hair", h[:4] + struct.pack("<I", 0xFFFFFFFF) * 2 + h[12:])]
    o = ok["obj"].decode()
    cases += [("obj-huge-index", "obj", (o + "\nl 1 9223372036854775808\n").encode()),
              ("obj-neg-huge-index", "obj", (o + "\nl -9223372036854775809 1\n").encode()),
              ("obj-nan", "obj", o.replace("v ", "v nan ", 1).encode()),
              ("obj-inf", "obj", ("v 1e999 0 0\n" + o).encode()),
              ("obj-index-zero", "obj", (o + "\nl 0 1\n").encode())]
    p = ok["ply"]
    cases += [("ply-count-huge", "ply", p.replace(b"element vertex", b"element vertex 99999999999999999999999 x", 1)),
              ("ply-ascii-nan", "ply", b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nelement strand 1\nproperty int count\nend_header\nnan 0 0\n1 1 1\n2\n")]
    pts = np.zeros((10, 3))
    pts[:, 0] = np.arange(10)
    base = {"format": np.array("hairport-hair"), "version": np.array(1), "units": np.array("m"),
            "points": pts, "offsets": np.array([0, 10])}
    cases += [("npz-bomb", "npz", npz_member_bomb(2_000_000)),
              ("npz-identical-2M", "npz", npz_bytes({**base, "points": np.zeros((2_000_000, 3)), "offsets": np.array([0, 2_000_000])})),
              ("npz-identical-2M+ok", "npz", npz_bytes({**base, "points": np.concatenate([pts, np.zeros((2_000_000, 3))]), "offsets": np.array([0, 10, 2_000_010])})),
              ("npz-offsets-huge", "npz", npz_bytes({**base, "offsets": np.array([0, 2**62])})),
              ("npz-offsets-neg", "npz", npz_bytes({**base, "offsets": np.array([0, -3, 10])})),
              ("npz-nan", "npz", npz_bytes({**base, "points": np.full((10, 3), np.nan)})),
              ("npz-cut", "npz", npz_bytes(base)[:100]),
              ("npz-2d-offsets", "npz", npz_bytes({**base, "offsets": np.array([[0, 10]])})),
              ("npz-version-huge", "npz", npz_bytes({**base, "version": np.array(2**62)})),
              ("npz-format-wrong", "npz", npz_bytes({**base, "format": np.array("x" * 100000)})),
              ]
    return cases

def mesh_cases(ok: dict) -> list[tuple[str, str, bytes]]:
    cases = []
    for ext, data in ok.items():
        cases += [(f"{ext}-empty", ext, b""), (f"{ext}-garbage", ext, _garbage(997)),
                  (f"{ext}-half", ext, data[: len(data) // 2]), (f"{ext}-head", ext, data[:7]),
                  (f"{ext}-nul", ext, b"\0" * 4096), (f"{ext}-deepjson", ext, deep_json())]
    o = ok["obj"].decode()
    cases += [("obj-face-2^63", "obj", (o + "\nf 1 2 9223372036854775808\n").encode()),
              ("obj-face-neg-2^63", "obj", (o + "\nf 1 2 -9223372036854775809\n").encode()),
              ("obj-face-float", "obj", (o + "\nf 1 2 3.5\n").encode()),
              ("obj-vertex-nan", "obj", ("v nan 0 0\n" + o).encode()),
              ("obj-vertex-1e999", "obj", ("v 1e999 0 0\n" + o).encode()),
              ("obj-face-oob", "obj", (o + "\nf 1 2 99999999\n").encode()),
              ("obj-2-corners", "obj", (o + "\nf 1 2\n").encode())]
    for label, patch in (("acc-count-huge", lambda d: d["accessors"][0].update(count=2**62)),
                         ("acc-count-neg", lambda d: d["accessors"][0].update(count=-1)),
                         ("buffer-uri-remote", lambda d: d["buffers"][0].update(uri="http://example.invalid/x.bin")),
                         ("buffer-uri-path", lambda d: d["buffers"][0].update(uri="../../../etc/passwd")),
                         ("buffer-uri-datahuge", lambda d: d["buffers"][0].update(uri="data:application/octet-stream;base64," + "A" * 100)),
                         ("mesh-index-huge", lambda d: d["meshes"][0]["primitives"][0].update(indices=2**63)),
                         ("node-cycle", lambda d: d.setdefault("nodes", [{}]) and d["nodes"][0].update(children=[0])),
                         ("strings", lambda d: d.update(accessors="x"))):
        doc = json.loads(ok["gltf"])
        patch(doc)
        cases.append((f"gltf-{label}", "gltf", json.dumps(doc).encode()))
    glb = ok["glb"]
    cases += [("glb-length-huge", "glb", glb[:8] + struct.pack("<I", 0xFFFFFFFF) + glb[12:]),
              ("glb-chunk-huge", "glb", glb[:12] + struct.pack("<I", 0xFFFFFFF0) + glb[16:]),
              ("glb-deep-json", "glb", _glb(deep_json()))]
    return cases

def _glb(js: bytes, binary: bytes = b"") -> bytes:
    js = js + b" " * (-len(js) % 4)
    body = struct.pack("<II", len(js), 0x4E4F534A) + js
    if binary:
        body += struct.pack("<II", len(binary), 0x004E4942) + binary
    return b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body

def skeleton_cases(skeleton: bytes) -> list[tuple[str, str, bytes]]:
    doc = json.loads(skeleton)
    out = [("sk-empty", b""), ("sk-deep", deep_json()), ("sk-deep-obj", b'{"a":' * 100000 + b"1" + b"}" * 100000),
           ("sk-garbage", _garbage(500)), ("sk-half", skeleton[: len(skeleton) // 2]), ("sk-nul", b"\0" * 100),
           ("sk-list", b"[]"), ("sk-number", b"1e999"), ("sk-nan", skeleton.replace(b"0.", b"NaN0.", 1))]
    for key in list(doc)[:6]:
        for label, value in (("bigint", 2**70), ("nested", [[[[[]]]]])):
            out.append((f"sk-{key}-{label}", json.dumps({**doc, key: value}).encode()))
    return [(name, "json", data) for name, data in out]
