"""Tests for solver/characterio.py: OBJ / PLY / glTF readers, skeleton sidecars, derived weights."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
import scipy.sparse as sp
import trimesh

from hairport.solver.io.character import (
    derive_skin_weights,
    fan_triangulate,
    load_character,
    load_skeleton_json,
    read_obj,
    resolve_skeleton_path,
    write_skeleton_json,
)
from hairport.solver.model.character import Skeleton
from hairport.solver.model.errors import InputError

# --------------------------------------------------------------------------------------
# synthetic inputs
# --------------------------------------------------------------------------------------


def make_body(n_rings: int = 16, n_around: int = 12, radius: float = 0.15, half_height: float = 0.75):
    """Closed surface of revolution around z: (vertices (V,3), quads (Q,4), triangles (T,3)).

    Quads join the rings, triangle fans close the ends at the two poles.
    """
    t = np.linspace(-1.0, 1.0, n_rings + 2)[1:-1]
    r = radius * (1.0 - np.abs(t) ** 6) ** (1.0 / 6.0)
    theta = 2.0 * np.pi * np.arange(n_around) / n_around
    rings = np.stack(
        [np.outer(r, np.cos(theta)), np.outer(r, np.sin(theta)), np.repeat(half_height * t[:, None], n_around, 1)],
        axis=2,
    ).reshape(-1, 3)
    vertices = np.concatenate([[[0.0, 0.0, -half_height]], rings, [[0.0, 0.0, half_height]]])
    top = len(vertices) - 1
    ring = lambda k, i: 1 + k * n_around + (i % n_around)  # noqa: E731
    k, i = np.meshgrid(np.arange(n_rings - 1), np.arange(n_around), indexing="ij")
    k, i = k.ravel(), i.ravel()
    quads = np.stack([ring(k, i), ring(k, i + 1), ring(k + 1, i + 1), ring(k + 1, i)], 1)
    i = np.arange(n_around)
    tris = np.concatenate(
        [
            np.stack([np.zeros(n_around, np.int64), ring(0, i + 1), ring(0, i)], 1),
            np.stack([np.full(n_around, top), ring(n_rings - 1, i), ring(n_rings - 1, i + 1)], 1),
        ]
    )
    return vertices, quads.astype(np.int64), tris.astype(np.int64)


def body_triangles(quads, tris):
    """Faces as the OBJ reader makes them: quads fanned, then the triangles, in that order."""
    return np.concatenate([fan_triangulate(quads.ravel(), np.full(len(quads), 4)), tris])


BONES = [
    {"name": "pelvis", "parent": None, "head": [0, 0, -0.5], "tail": [0, 0, -0.1]},
    {"name": "spine", "parent": "pelvis", "head": [0, 0, -0.1], "tail": [0, 0, 0.3]},
    {"name": "head", "parent": "spine", "head": [0, 0, 0.3], "tail": [0, 0, 0.6]},
]


def write_obj(path, vertices, polygons, with_attributes: bool = False):
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
        body = struct.pack("<II", len(text), 0x4E4F534A) + text + struct.pack("<II", len(self.blob), 0x004E4942)
        body += bytes(self.blob)
        return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body

    def gltf(self, path, external: bool):
        self.blob += b"\0" * (-len(self.blob) % 4)
        if external:
            (path.parent / "buffer.bin").write_bytes(bytes(self.blob))
            uri = "buffer.bin"
        else:
            import base64

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


BONES_HEADS = [b["head"] for b in BONES]


# --------------------------------------------------------------------------------------
# OBJ
# --------------------------------------------------------------------------------------


def test_obj_with_vt_vn_keeps_vertex_count_and_order(tmp_path):
    vertices, quads, tris = make_body()
    polygons = list(quads) + list(tris)
    path = tmp_path / "body.obj"
    write_obj(path, vertices, polygons, with_attributes=True)
    character = load_character(path)
    np.testing.assert_array_equal(character.vertices, vertices)  # exact: same floats, same order
    np.testing.assert_array_equal(character.faces, body_triangles(quads, tris))
    assert character.skeleton is None and character.name == "body.obj"
    # plain indices give the same topology
    plain = tmp_path / "plain.obj"
    write_obj(plain, vertices, polygons)
    np.testing.assert_array_equal(load_character(plain).faces, character.faces)


def test_obj_polygons_negative_indices_and_extras(tmp_path):
    path = tmp_path / "poly.obj"
    path.write_text(
        "mtllib x.mtl\nv 0 0 0 1\nv 1 0 0\nv 1 1 0 0.5 0.5 0.5\nv 0 1 0\n"
        "g a\nusemtl m\nf -4 -3 -2 -1\nv 0.5 0.5 1\nvn 0 0 1\nf 1//1 2//1 5//1   # comment\n"
        "f 2 3 \\\n 4 5 1\ns off\nl 1 2\n"
    )
    vertices, faces = read_obj(path)
    np.testing.assert_array_equal(vertices, [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0.5, 0.5, 1]])
    np.testing.assert_array_equal(faces, [[0, 1, 2], [0, 2, 3], [0, 1, 4], [1, 2, 3], [1, 3, 4], [1, 4, 0]])


def test_fan_triangulate():
    faces = fan_triangulate(np.array([5, 6, 7, 1, 2, 3, 4, 8]), np.array([3, 5]))
    np.testing.assert_array_equal(faces, [[5, 6, 7], [1, 2, 3], [1, 3, 4], [1, 4, 8]])


@pytest.mark.parametrize(
    "text, code",
    [
        ("v 0 0 0\nv 1 0 0\nf 1 2\n", "bad_faces"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "bad_faces"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n", "bad_faces"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n", "bad_faces"),
        ("v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n", "non_finite"),
        ("v 0 0 0\nv 1 0\nv 0 1 0\nf 1 2 3\n", "bad_mesh"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "empty_mesh"),
        ("# nothing\n", "empty_mesh"),
    ],
)
def test_obj_bad_input(tmp_path, text, code):
    path = tmp_path / "bad.obj"
    path.write_text(text)
    with pytest.raises(InputError) as error:
        load_character(path)
    assert error.value.code == code
    assert error.value.source == str(path)
    assert str(path) in str(error.value)


def test_file_errors(tmp_path):
    with pytest.raises(InputError) as error:
        load_character(tmp_path / "missing.obj")
    assert error.value.code == "not_found"
    (tmp_path / "mesh.stl").write_text("solid x\n")
    with pytest.raises(InputError) as error:
        load_character(tmp_path / "mesh.stl")
    assert error.value.code == "unknown_format"
    (tmp_path / "empty.obj").write_bytes(b"")
    with pytest.raises(InputError) as error:
        load_character(tmp_path / "empty.obj")
    assert error.value.code == "empty_mesh"


def test_limits(tmp_path):
    vertices, quads, tris = make_body()
    path = tmp_path / "body.obj"
    write_obj(path, vertices, list(quads) + list(tris))
    with pytest.raises(InputError, match="vertices") as error:
        load_character(path, max_vertices=100)
    assert error.value.code == "too_large"
    with pytest.raises(InputError, match="triangles|faces") as error:
        load_character(path, max_faces=len(quads) + len(tris))  # fine as polygons, too many triangles
    assert error.value.code == "too_large"
    with pytest.raises(InputError) as error:
        load_character(path, max_bytes=100)
    assert error.value.code == "too_large"


def test_units_conversion(tmp_path):
    vertices, quads, tris = make_body()
    path = tmp_path / "body.obj"
    write_obj(path, vertices * 10.0, list(quads) + list(tris))
    character = load_character(path, units="dm")
    np.testing.assert_allclose(character.vertices, vertices, rtol=1e-15, atol=1e-15)
    with pytest.raises(InputError) as error:
        load_character(path, units="inch")
    assert error.value.code == "unknown_units"


# --------------------------------------------------------------------------------------
# PLY
# --------------------------------------------------------------------------------------


def test_ply_with_per_face_texcoords_keeps_vertices(tmp_path):
    path = tmp_path / "quads.ply"
    path.write_text(
        "ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\nproperty float z\n"
        "element face 2\nproperty list uchar int vertex_indices\nproperty list uchar float texcoord\nend_header\n"
        "0 0 0\n1 0 0\n1 1 0\n0 1 0\n2 0 0\n2 1 0\n"
        "4 0 1 2 3 8 0 0 1 0 1 1 0 1\n4 1 4 5 2 8 0.1 0 1 0 1 1 0 1\n"
    )
    character = load_character(path)
    assert character.n_vertices == 6 and character.n_faces == 4
    np.testing.assert_array_equal(character.vertices[4], [2, 0, 0])


def test_binary_ply_and_header_limits(tmp_path):
    vertices, quads, tris = make_body()
    faces = body_triangles(quads, tris)
    face_dtype = np.dtype([("n", "u1"), ("i", "<i4", (3,))])
    face_data = np.zeros(len(faces), face_dtype)
    face_data["n"], face_data["i"] = 3, faces
    header = (
        f"ply\nformat binary_little_endian 1.0\nelement vertex {len(vertices)}\nproperty double x\n"
        f"property double y\nproperty double z\nelement face {len(faces)}\n"
        "property list uchar int vertex_indices\nend_header\n"
    ).encode()
    path = tmp_path / "body.ply"
    path.write_bytes(header + vertices.astype("<f8").tobytes() + face_data.tobytes())
    character = load_character(path)
    np.testing.assert_array_equal(character.vertices, vertices)
    np.testing.assert_array_equal(character.faces, faces)
    with pytest.raises(InputError) as error:
        load_character(path, max_faces=10)
    assert error.value.code == "too_large"
    (tmp_path / "junk.ply").write_bytes(b"not a ply")
    with pytest.raises(InputError):
        load_character(tmp_path / "junk.ply")


# --------------------------------------------------------------------------------------
# skeleton sidecar
# --------------------------------------------------------------------------------------


def body_obj(tmp_path, scale=1.0):
    vertices, quads, tris = make_body()
    path = tmp_path / "body.obj"
    write_obj(path, vertices * scale, list(quads) + list(tris))
    return path, vertices, body_triangles(quads, tris)


def test_skeleton_roundtrip_in_centimeters(tmp_path):
    path, vertices, faces = body_obj(tmp_path)
    skeleton = Skeleton([b["name"] for b in BONES], [-1, 0, 1], [b["head"] for b in BONES],
                        [b["tail"] for b in BONES])
    rng = np.random.default_rng(3)
    dense = rng.random((len(vertices), 3)) * (rng.random((len(vertices), 3)) < 0.5)
    dense[0] = 0  # an unweighted vertex stays unweighted
    dense[1:] /= np.maximum(dense[1:].sum(axis=1, keepdims=True), 1e-300)
    dense[1:][dense[1:].sum(axis=1) == 0, 0] = 1.0
    weights = sp.csr_matrix(dense)
    sidecar = tmp_path / "out" / "rig.json"
    write_skeleton_json(sidecar, skeleton, weights, units="cm")
    assert [p.name for p in sidecar.parent.iterdir()] == ["rig.json"]  # no temp file left
    document = json.loads(sidecar.read_text())
    assert document["units"] == "cm" and document["bones"][1]["parent"] == "pelvis"
    assert document["bones"][2]["head"] == pytest.approx([0, 0, 30])
    loaded, loaded_weights = load_skeleton_json(sidecar, len(vertices))
    np.testing.assert_allclose(loaded.heads, skeleton.heads, atol=1e-15)
    np.testing.assert_allclose(loaded.tails, skeleton.tails, atol=1e-15)
    np.testing.assert_array_equal(loaded.parents, skeleton.parents)
    np.testing.assert_allclose(loaded_weights.toarray(), dense, atol=1e-15)


def test_sidecar_is_found_and_sets_mesh_units(tmp_path):
    path, vertices, faces = body_obj(tmp_path, scale=100.0)  # mesh written in cm
    bones = [dict(b, head=[100 * x for x in b["head"]], tail=[100 * x for x in b["tail"]]) for b in BONES]
    weights = {"pelvis": [[i, 1.0] for i in range(len(vertices))], "spine": [[0, 3.0], [0, 1.0]]}
    sidecar = tmp_path / "body.skeleton.json"
    sidecar.write_text(json.dumps({"units": "cm", "bones": bones, "weights": weights, "extra": 1}))
    assert resolve_skeleton_path(path) == sidecar
    character = load_character(path)
    np.testing.assert_allclose(character.vertices, vertices, rtol=1e-14, atol=1e-15)
    np.testing.assert_allclose(character.skeleton.heads, [b["head"] for b in BONES], atol=1e-15)
    # rows normalised; duplicate entries summed: vertex 0 has pelvis 1, spine 4 -> 0.2 / 0.8
    np.testing.assert_allclose(character.weights[0].toarray(), [[0.2, 0.8, 0.0]])
    np.testing.assert_allclose(np.asarray(character.weights.sum(axis=1)).ravel(), 1.0)
    # explicit units win over the sidecar's
    assert np.allclose(load_character(path, units="m").vertices, vertices * 100.0)


def test_no_sidecar_means_no_skeleton(tmp_path):
    path, _, _ = body_obj(tmp_path)
    assert resolve_skeleton_path(path) is None
    assert load_character(path).skeleton is None
    with pytest.raises(InputError) as error:
        load_character(path, skeleton_path=tmp_path / "nope.json")
    assert error.value.code == "not_found"


def _bones(**changes):
    bones = [dict(b) for b in BONES]
    for index, change in changes.items():
        bones[int(index[1:])].update(change)
    return bones


@pytest.mark.parametrize(
    "document, code, words",
    [
        ({"bones": _bones(b1={"parent": "hips"})}, "bad_skeleton", "unknown parent"),
        ({"bones": _bones(b2={"name": "spine"})}, "bad_skeleton", "duplicate"),
        ({"bones": _bones(b0={"parent": "head"})}, "bad_skeleton", "cycle"),
        ({"bones": _bones(b1={"parent": "spine"})}, "bad_skeleton", "cycle"),
        ({"bones": _bones(b1={"head": [0, "x", 0]})}, "bad_skeleton", "3 numbers"),
        ({"bones": _bones(b1={"tail": [0, 0]})}, "bad_skeleton", "3 numbers"),
        ({"bones": _bones(b1={"tail": [0, float("inf"), 0]})}, "non_finite", "non-finite"),
        ({"bones": []}, "bad_skeleton", "bones"),
        ({"units": "ft", "bones": BONES}, "unknown_units", "unit"),
        ({"bones": BONES, "weights": {"tail": [[0, 1]]}}, "bad_weights", "unknown bone"),
        ({"bones": BONES, "weights": {"head": [[100000, 1]]}}, "bad_weights", "outside"),
        ({"bones": BONES, "weights": {"head": [[-1, 1]]}}, "bad_weights", "outside"),
        ({"bones": BONES, "weights": {"head": [[1.5, 1]]}}, "bad_weights", "non-integer"),
        ({"bones": BONES, "weights": {"head": [[1, -0.5]]}}, "bad_weights", "negative"),
        ({"bones": BONES, "weights": {"head": [[1, float("nan")]]}}, "non_finite", "non-finite"),
        ({"bones": BONES, "weights": {"head": [[1, 2, 3]]}}, "bad_weights", "pairs"),
        ({"bones": BONES, "weights": [1, 2]}, "bad_weights", "object"),
        ([1, 2], "bad_skeleton", "object"),
    ],
)
def test_sidecar_validation(tmp_path, document, code, words):
    path = tmp_path / "rig.json"
    path.write_text(json.dumps(document))  # json writes NaN / Infinity tokens, as some exporters do
    with pytest.raises(InputError) as error:
        load_skeleton_json(path, 100)
    assert error.value.code == code
    assert words in error.value.problem
    assert error.value.source == str(path)


def test_sidecar_not_json(tmp_path):
    path = tmp_path / "rig.json"
    path.write_text("{bones: ")
    with pytest.raises(InputError, match="JSON") as error:
        load_skeleton_json(path, 10)
    assert error.value.code == "bad_skeleton"


# --------------------------------------------------------------------------------------
# derived weights
# --------------------------------------------------------------------------------------


def test_derived_weights_follow_the_bones(tmp_path):
    path, vertices, _ = body_obj(tmp_path)
    (tmp_path / "body.skeleton.json").write_text(json.dumps({"units": "m", "bones": BONES}))
    character = load_character(path)
    weights = character.weights.toarray()
    np.testing.assert_allclose(weights.sum(axis=1), 1.0)
    assert (weights >= 0).all()
    z = vertices[:, 2]
    assert (weights[z < -0.3].argmax(axis=1) == 0).all()
    assert (weights[(z > 0.0) & (z < 0.2)].argmax(axis=1) == 1).all()
    assert (weights[z > 0.45].argmax(axis=1) == 2).all()
    # smoothing blends across the border at z = -0.1, hard weights do not
    assert ((weights > 0.05) & (weights < 0.95)).any()
    hard = load_character(path, weight_smoothing=0).weights
    assert set(np.unique(hard.data)) == {1.0}


def test_derived_weights_respect_visibility():
    """A vertex of sphere A nearer to bone b (inside sphere B, behind B's wall) goes to bone a."""
    a = trimesh.creation.icosphere(subdivisions=3, radius=1.0)
    b = trimesh.creation.icosphere(subdivisions=2, radius=0.5)
    vertices = np.concatenate([a.vertices, b.vertices + [2.0, 0.0, 0.0]])
    faces = np.concatenate([a.faces, b.faces + len(a.vertices)])
    skeleton = Skeleton(("a", "b"), [-1, -1], [[-0.05, 0, 0], [1.6, 0, -0.05]], [[0.05, 0, 0], [1.6, 0, 0.05]])
    weights = derive_skin_weights(vertices, faces, skeleton, smoothing=0).toarray()
    right_pole = int(np.argmax(a.vertices[:, 0]))
    assert np.linalg.norm(vertices[right_pole] - [1.6, 0, 0]) < np.linalg.norm(vertices[right_pole])
    assert weights[right_pole, 0] == 1.0
    assert (weights[: len(a.vertices), 0] == 1.0).all()
    assert (weights[len(a.vertices):, 1] == 1.0).all()
    smoothed = derive_skin_weights(vertices, faces, skeleton)
    np.testing.assert_allclose(smoothed.toarray(), weights)  # no edges join the spheres


# --------------------------------------------------------------------------------------
# glTF / GLB
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("with_inverse_bind", [True, False])
def test_glb_skin(tmp_path, with_inverse_bind):
    builder, vertices, faces, weights = skinned_body_gltf(with_inverse_bind, extra_mesh=True)
    path = tmp_path / "body.glb"
    path.write_bytes(builder.glb())
    character = load_character(path)
    # skinned mesh chosen over the bigger prop; its node transform is ignored (glTF spec)
    np.testing.assert_allclose(character.vertices, vertices, atol=1e-6)
    np.testing.assert_array_equal(character.faces, faces)
    skeleton = character.skeleton
    assert skeleton.names == ("root", "spine", "head")
    np.testing.assert_array_equal(skeleton.parents, [-1, 0, 1])
    np.testing.assert_allclose(skeleton.heads, BONES_HEADS, atol=1e-6)
    # tails: the child's head; the leaf extends half its parent distance
    np.testing.assert_allclose(skeleton.tails, [[0, 0, -0.1], [0, 0, 0.3], [0, 0, 0.5]], atol=1e-6)
    expected = np.zeros((len(vertices), 3))
    rounded = np.round(weights * 255) / 255
    joints_used = np.argsort(np.abs(vertices[:, None, 2] - (np.array(BONES_HEADS)[:, 2] + 0.2)[None]), axis=1)[:, :2]
    np.put_along_axis(expected, joints_used, rounded[:, :2], axis=1)
    expected /= expected.sum(axis=1, keepdims=True)
    np.testing.assert_allclose(character.weights.toarray(), expected, atol=1e-12)


@pytest.mark.parametrize("external", [True, False])
def test_gltf_buffers(tmp_path, external):
    builder, vertices, _, _ = skinned_body_gltf()
    path = tmp_path / "body.gltf"
    builder.gltf(path, external)
    character = load_character(path, units="cm")  # explicit units scale mesh and skin alike
    np.testing.assert_allclose(character.vertices, vertices * 0.01, atol=1e-8)
    np.testing.assert_allclose(character.skeleton.heads, np.array(BONES_HEADS) * 0.01, atol=1e-8)


def test_gltf_sidecar_wins_over_skin(tmp_path):
    builder, vertices, _, _ = skinned_body_gltf()
    path = tmp_path / "body.glb"
    path.write_bytes(builder.glb())
    (tmp_path / "body.skeleton.json").write_text(json.dumps({"bones": BONES[:2]}))
    assert load_character(path).skeleton.names == ("pelvis", "spine")


def test_gltf_unskinned_meshes(tmp_path):
    box = trimesh.creation.box()
    builder = GltfBuilder()
    m1 = builder.mesh(box.vertices, box.faces, "left")
    m2 = builder.mesh(box.vertices, box.faces, "right")
    builder.node(name="left_node", mesh=m1, translation=[-2, 0, 0])
    builder.node(name="right_node", mesh=m2, translation=[2, 0, 0], scale=[-1, 1, 1])
    path = tmp_path / "two.glb"
    path.write_bytes(builder.glb())
    with pytest.raises(InputError) as error:
        load_character(path)
    assert error.value.code == "ambiguous_mesh"
    assert "left_node" in error.value.problem and "right_node" in error.value.problem
    left = load_character(path, mesh_name="left_node")
    np.testing.assert_allclose(left.vertices, box.vertices + [-2, 0, 0], atol=1e-6)
    right = load_character(path, mesh_name="right")  # by mesh name; mirrored -> winding flipped
    np.testing.assert_allclose(right.vertices, box.vertices * [-1, 1, 1] + [2, 0, 0], atol=1e-6)
    np.testing.assert_array_equal(right.faces, box.faces[:, [0, 2, 1]])
    assert right.skeleton is None
    with pytest.raises(InputError, match="no mesh named"):
        load_character(path, mesh_name="middle")


def test_glb_bad_input(tmp_path):
    builder, _, _, _ = skinned_body_gltf()
    data = builder.glb()
    path = tmp_path / "cut.glb"
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError) as error:
        load_character(path)
    assert error.value.code == "truncated"
    # an accessor that claims more elements than its bufferView holds
    builder, _, _, _ = skinned_body_gltf()
    builder.doc["accessors"][0]["count"] += 10
    path.write_bytes(builder.glb())
    with pytest.raises(InputError) as error:
        load_character(path)
    assert error.value.code == "truncated"
    # limits are checked from the accessor counts
    builder, _, _, _ = skinned_body_gltf()
    path.write_bytes(builder.glb())
    with pytest.raises(InputError) as error:
        load_character(path, max_vertices=10)
    assert error.value.code == "too_large"
    # a buffer uri escaping the folder is refused
    builder, _, _, _ = skinned_body_gltf()
    builder.gltf(tmp_path / "x.gltf", external=True)
    document = json.loads((tmp_path / "x.gltf").read_text())
    document["buffers"][0]["uri"] = "../../etc/passwd"
    (tmp_path / "x.gltf").write_text(json.dumps(document))
    with pytest.raises(InputError, match="relative path"):
        load_character(tmp_path / "x.gltf")


def test_corrupted_glb_gives_input_errors_only(tmp_path):
    builder, _, _, _ = skinned_body_gltf()
    data = bytearray(builder.glb())
    json_length = struct.unpack_from("<I", data, 12)[0]
    rng = np.random.default_rng(11)
    path = tmp_path / "fuzz.glb"
    for trial in range(60):
        corrupted = bytearray(data)
        if trial % 3 == 0:  # truncate anywhere
            corrupted = corrupted[: int(rng.integers(0, len(data)))]
        else:  # flip a few bytes, mostly in the JSON chunk
            end = 20 + json_length if trial % 3 == 1 else len(data)
            for position in rng.integers(0, end, 3):
                corrupted[position] = int(rng.integers(0, 256))
        path.write_bytes(bytes(corrupted))
        try:
            load_character(path)
        except InputError:
            pass


@pytest.mark.parametrize(
    "document",
    [
        {"bones": [None]},
        {"bones": [{"name": "a", "parent": None, "head": [10**400, 0, 0], "tail": [0, 0, 1]}]},
        {"bones": "abc"},
        {"bones": BONES, "weights": {"head": "abc"}},
        {"bones": BONES, "weights": {"head": [[1, [2]]]}},
        {"bones": BONES, "weights": {"head": [None]}},
        {"units": None, "bones": BONES},
    ],
)
def test_malformed_sidecar_gives_input_error(tmp_path, document):
    path = tmp_path / "rig.json"
    path.write_text(json.dumps(document))
    with pytest.raises(InputError):
        load_skeleton_json(path, 100)
