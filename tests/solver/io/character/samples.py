"""Sample character files for the reader tests: the capsule body as OBJ, a skinned glTF / GLB of it."""

from __future__ import annotations

import base64
import json
import struct

import numpy as np
import trimesh

from hairport.solver.io.character.gltf.buffers import GLB_BIN_CHUNK, GLB_JSON_CHUNK, GLB_MAGIC
from hairport.solver.io.character.obj import fan_triangulate
from tests.solver.capsule import CHAIN_HEADS, CHAIN_NAMES, CHAIN_PARENTS, CHAIN_TAILS, capsule


def make_body():
    """The capsule body with 16 rings of 12: (vertices (V,3), quads (Q,4), triangles (T,3)).

    Quads join the rings, triangle fans close the ends at the two poles.
    """
    vertices, quads, bottom, top = capsule(16, 12)
    return vertices, quads, np.concatenate([bottom, top])


def body_triangles(quads, tris):
    """Faces as the OBJ reader makes them: quads fanned, then the triangles, in that order."""
    return np.concatenate([fan_triangulate(quads.ravel(), np.full(len(quads), 4)), tris])


#: the bone chain as sidecar JSON bones
BONES = [
    {"name": name, "parent": CHAIN_NAMES[parent] if parent >= 0 else None, "head": list(head), "tail": list(tail)}
    for name, parent, head, tail in zip(CHAIN_NAMES, CHAIN_PARENTS, CHAIN_HEADS, CHAIN_TAILS)
]
BONES_HEADS = [b["head"] for b in BONES]


def write_obj_polygons(path, vertices, polygons, with_attributes: bool = False):
    """Write an OBJ; with attributes every corner gets its own vt and a shared vn (like exporters)."""
    lines = ["# test", "o body"]
    lines += [f"v {x!r} {y!r} {z!r}" for x, y, z in vertices.tolist()]
    if with_attributes:
        n_corners = sum(len(p) for p in polygons)
        lines += [f"vt {u / n_corners!r} 0.5" for u in range(n_corners)]
        lines += ["vn 0 0 1", "vn 0 1 0"]
    corner = 0
    for p in polygons:
        if with_attributes:
            parts = []
            for v in p:
                corner += 1
                parts.append(f"{v + 1}/{corner}/{1 + corner % 2}")
            lines.append("f " + " ".join(parts))
        else:
            lines.append("f " + " ".join(str(v + 1) for v in p))
    path.write_text("\n".join(lines) + "\n")


class GltfBuilder:
    """Write small glTF / GLB files with numpy: one buffer, one bufferView per accessor."""

    def __init__(self):
        self.blob = bytearray()
        self.doc = {"asset": {"version": "2.0"}, "buffers": [], "bufferViews": [], "accessors": [],
                    "meshes": [], "nodes": [], "scenes": [{"nodes": []}], "scene": 0}

    def accessor(self, array, kind, component, normalized=False):
        array = np.ascontiguousarray(array)
        self.blob += b"\0" * (-len(self.blob) % 4)
        self.doc["bufferViews"].append({"buffer": 0, "byteOffset": len(self.blob), "byteLength": array.nbytes})
        self.blob += array.tobytes()
        accessor = {"bufferView": len(self.doc["bufferViews"]) - 1, "componentType": component,
                    "count": len(array), "type": kind}
        if normalized:
            accessor["normalized"] = True
        self.doc["accessors"].append(accessor)
        return len(self.doc["accessors"]) - 1

    def mesh(self, vertices, faces, name, joints=None, weights=None):
        attributes = {"POSITION": self.accessor(vertices.astype("<f4"), "VEC3", 5126)}
        if joints is not None:
            attributes["JOINTS_0"] = self.accessor(joints.astype("<u2"), "VEC4", 5123)
            attributes["WEIGHTS_0"] = self.accessor(np.round(weights * 255).astype("u1"), "VEC4", 5121, True)
        indices = self.accessor(faces.astype("<u4").ravel(), "SCALAR", 5125)
        self.doc["meshes"].append({"name": name, "primitives": [{"attributes": attributes, "indices": indices}]})
        return len(self.doc["meshes"]) - 1

    def node(self, **node):
        self.doc["nodes"].append(node)
        return len(self.doc["nodes"]) - 1

    def skin(self, joints, inverse_bind):
        skin = {"joints": joints}
        if inverse_bind is not None:
            column_major = np.transpose(inverse_bind, (0, 2, 1)).reshape(-1, 16).astype("<f4")
            skin["inverseBindMatrices"] = self.accessor(column_major, "MAT4", 5126)
        self.doc.setdefault("skins", []).append(skin)
        return len(self.doc["skins"]) - 1

    def glb(self) -> bytes:
        self.blob += b"\0" * (-len(self.blob) % 4)
        self.doc["buffers"] = [{"byteLength": len(self.blob)}]
        text = json.dumps(self.doc).encode()
        text += b" " * (-len(text) % 4)
        body = struct.pack("<II", len(text), GLB_JSON_CHUNK) + text + struct.pack("<II", len(self.blob), GLB_BIN_CHUNK)
        body += bytes(self.blob)
        return GLB_MAGIC + struct.pack("<II", 2, 12 + len(body)) + body

    def gltf(self, path, external: bool):
        self.blob += b"\0" * (-len(self.blob) % 4)
        if external:
            (path.parent / "buffer.bin").write_bytes(bytes(self.blob))
            uri = "buffer.bin"
        else:
            uri = "data:application/octet-stream;base64," + base64.b64encode(bytes(self.blob)).decode()
        self.doc["buffers"] = [{"byteLength": len(self.blob), "uri": uri}]
        path.write_text(json.dumps(self.doc))


def rotation_x_quaternion(angle):
    return [np.sin(angle / 2), 0.0, 0.0, np.cos(angle / 2)]


def skinned_body_gltf(with_inverse_bind: bool = True, extra_mesh: bool = False) -> GltfBuilder:
    """The body skinned to a 3-joint chain along z, built with a rotated node hierarchy.

    Joint world positions: (0, 0, -0.5), (0, 0, -0.1), (0, 0, 0.3).
    """
    vertices, quads, tris = make_body()
    faces = body_triangles(quads, tris)
    heads = np.array(BONES_HEADS)
    d = np.abs(vertices[:, None, 2] - (heads[:, 2] + 0.2)[None])
    order = np.argsort(d, axis=1)[:, :2]
    joints = np.concatenate([order, np.zeros((len(vertices), 2), np.int64)], axis=1)
    w2 = np.take_along_axis(d, order, axis=1)
    share = (w2[:, ::-1] / w2.sum(axis=1, keepdims=True))
    weights = np.concatenate([share, np.zeros((len(vertices), 2))], axis=1)
    builder = GltfBuilder()
    mesh = builder.mesh(vertices, faces, "body", joints, weights)
    # hierarchy: armature (not a joint) -> root (rotated 90 deg about x) -> spine -> head
    builder.node(name="armature", children=[1])
    builder.node(name="root", translation=[0, 0, -0.5], rotation=rotation_x_quaternion(np.pi / 2), children=[2])
    builder.node(name="spine", translation=[0, 0.4, 0], children=[3])
    builder.node(name="head", translation=[0, 0.4, 0])
    rot = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float)
    worlds = []
    for h in heads:
        m = np.eye(4)
        m[:3, :3] = rot
        m[:3, 3] = h
        worlds.append(m)
    skin = builder.skin([1, 2, 3], np.linalg.inv(np.array(worlds)) if with_inverse_bind else None)
    builder.node(name="body_node", mesh=mesh, skin=skin, translation=[5, 5, 5])
    builder.doc["scenes"][0]["nodes"] = [0, 4]
    if extra_mesh:  # a bigger unskinned mesh: the skinned one must still win
        big = trimesh.creation.icosphere(subdivisions=3)
        builder.node(name="prop", mesh=builder.mesh(big.vertices, big.faces, "prop"))
    return builder, vertices, faces, weights


def body_obj(tmp_path, scale=1.0):
    """``body.obj`` in ``tmp_path`` (coordinates times ``scale``): (path, vertices, faces as read)."""
    vertices, quads, tris = make_body()
    path = tmp_path / "body.obj"
    write_obj_polygons(path, vertices * scale, list(quads) + list(tris))
    return path, vertices, body_triangles(quads, tris)
