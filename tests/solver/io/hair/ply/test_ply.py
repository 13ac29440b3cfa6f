"""Polyline PLY files: strand layouts (a)-(d) and the writer (:mod:`hairport.solver.io.hair.ply`)."""

from __future__ import annotations

import numpy as np
import pytest

from hairport.solver.io.hair import (
    HairIOWarning,
    ReadLimits,
    hair_to_bytes,
    read_hair,
    read_hair_bytes,
    read_hair_bytes_report,
    write_hair,
)
from hairport.solver.io.hair.common import ReadContext
from hairport.solver.io.hair.ply import counts_from_edges, counts_from_ids, edge_starts, vertex_columns
from hairport.solver.model.hair import Hair, HairAttribute
from tests.solver.io.hair.samples import (
    ASCII_PLY,
    PLY_ENCODINGS,
    XYZ,
    expect_error,
    f32,
    helix_hair,
    long_strand_hair,
    ply_bytes,
    strands_of,
    xyz_props,
)

CONTEXT = ReadContext("s.ply", ReadLimits(), "m")


@pytest.mark.parametrize("ascii", [False, True])
def test_ply_keeps_thickness_exactly_and_color_to_8_bits(tmp_path, groom, ascii):
    write_hair(tmp_path / "g.ply", groom, ascii=ascii)
    back = read_hair(tmp_path / "g.ply")
    np.testing.assert_array_equal(back.thickness, f32(groom.thickness))
    assert np.abs(back.color - groom.color).max() <= 0.5 / 255 + 1e-12


#: strands longer than the default per-strand limit (format round trips of 2^16 points)
LONG_STRANDS = ReadLimits(max_strand_particles=100_000)


def test_ascii_and_binary_ply_read_equal(tmp_path, groom):
    write_hair(tmp_path / "a.ply", groom, ascii=True)
    write_hair(tmp_path / "b.ply", groom)
    assert (tmp_path / "a.ply").read_bytes().split(b"\n")[1] == b"format ascii 1.0"
    assert (tmp_path / "b.ply").read_bytes().split(b"\n")[1] == b"format binary_little_endian 1.0"
    a, b = read_hair(tmp_path / "a.ply"), read_hair(tmp_path / "b.ply")
    for name in ("points", "offsets", "thickness", "color"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_written_ply_header_layout(tmp_path, groom):
    write_hair(tmp_path / "g.ply", groom)
    head = (tmp_path / "g.ply").read_bytes().split(b"end_header\n")[0].decode().splitlines()
    n, s = groom.n_particles, groom.n_strands
    assert head[3:] == [
        f"element vertex {n}",
        "property float x",
        "property float y",
        "property float z",
        "property float thickness",
        "property uchar red",
        "property uchar green",
        "property uchar blue",
        f"element strand {s}",
        "property ushort nsegs",
        f"element edge {n - s}",
        "property int vertex1",
        "property int vertex2",
    ]


@pytest.mark.parametrize("encoding", PLY_ENCODINGS)
@pytest.mark.parametrize("counts", [[4, 4, 4], [3, 5, 2, 6]], ids=["uniform", "varied"])
def test_ply_vertex_index_lists(encoding, counts):
    points, offsets = strands_of(counts)
    lists = [list(range(offsets[s], offsets[s + 1])) for s in range(len(counts))]
    lists[1] = lists[1][::-1]  # indices need not run in file order
    data = ply_bytes(
        encoding,
        [
            ("vertex", len(points), xyz_props(points)),
            ("curve", len(counts), [("vertex_indices", ("list", "uchar", "int"), lists)]),
        ],
    )
    hair = read_hair_bytes(data, "ply")
    np.testing.assert_array_equal(hair.offsets, offsets)
    np.testing.assert_array_equal(hair.points, points[np.concatenate(lists)])


def test_ply_index_out_of_range():
    points, _ = strands_of([2])
    data = ply_bytes(
        "ascii",
        [
            ("vertex", 2, xyz_props(points)),
            ("strand", 1, [("vertex_indices", ("list", "uchar", "int"), [[0, 2]])]),
        ],
    )
    err = expect_error("bad_index", read_hair_bytes, data, "ply")
    assert "vertex 2" in str(err)


@pytest.mark.parametrize("encoding", PLY_ENCODINGS)
def test_ply_hairutil_nsegs_layout(encoding):
    """hairutil writes ``element strand`` with ``ushort nsegs`` and uchar colors."""
    counts = [3, 2, 5]
    points, offsets = strands_of(counts)
    rgb = np.random.default_rng(1).integers(0, 256, (10, 3))
    props = xyz_props(points) + [
        (c, "uchar", [int(v) for v in rgb[:, i]]) for i, c in enumerate(("red", "green", "blue"))
    ]
    data = ply_bytes(
        encoding, [("vertex", 10, props), ("strand", 3, [("nsegs", "ushort", [2, 1, 4])])]
    )
    hair = read_hair_bytes(data, "ply")
    np.testing.assert_array_equal(hair.offsets, offsets)
    np.testing.assert_array_equal(hair.points, points)
    np.testing.assert_allclose(hair.color, rgb / 255)


def test_ply_point_count_property_and_float_colors():
    points, offsets = strands_of([2, 3])
    props = xyz_props(points) + [
        ("red", "float", [0.25] * 5),
        ("green", "float", [0.5] * 5),
        ("blue", "float", [1.0] * 5),
    ]
    data = ply_bytes(
        "binary_little_endian",
        [("vertex", 5, props), ("strands", 2, [("vertex_count", "int", [2, 3])])],
    )
    hair = read_hair_bytes(data, "ply")
    np.testing.assert_array_equal(hair.offsets, offsets)
    np.testing.assert_array_equal(hair.color, np.tile([0.25, 0.5, 1.0], (5, 1)))


def test_ply_strand_counts_must_cover_the_vertices():
    points, _ = strands_of([2, 3])
    data = ply_bytes(
        "ascii", [("vertex", 5, xyz_props(points)), ("strand", 2, [("nsegs", "ushort", [1, 1])])]
    )
    err = expect_error("bad_index", read_hair_bytes, data, "ply")
    assert "hold 4 points but there are 5 vertices" in str(err)


@pytest.mark.parametrize("encoding", PLY_ENCODINGS)
def test_ply_per_vertex_strand_id(encoding):
    points, offsets = strands_of([3, 2, 4])
    ids = [7, 7, 7, 2, 2, 9, 9, 9, 9]
    data = ply_bytes(encoding, [("vertex", 9, xyz_props(points) + [("strand_id", "int", ids)])])
    hair = read_hair_bytes(data, "ply")
    np.testing.assert_array_equal(hair.offsets, offsets)
    np.testing.assert_array_equal(hair.points, points)


def test_ply_strand_id_must_be_consecutive():
    points, _ = strands_of([4])
    data = ply_bytes(
        "ascii", [("vertex", 4, xyz_props(points) + [("strand_id", "int", [0, 0, 1, 0])])]
    )
    expect_error("bad_index", read_hair_bytes, data, "ply")


@pytest.mark.parametrize("encoding", PLY_ENCODINGS)
def test_ply_edges_only(encoding):
    points, _ = strands_of([3, 1, 2])  # vertex 3 is on no edge: a one-point strand
    v1, v2 = [4, 0, 1], [5, 1, 2]  # any order
    data = ply_bytes(
        encoding,
        [
            ("vertex", 6, xyz_props(points)),
            ("edge", 3, [("vertex1", "int", v1), ("vertex2", "int", v2)]),
        ],
    )
    report = read_hair_bytes_report(data, "ply")
    np.testing.assert_array_equal(report.hair.offsets, [0, 3, 5])
    np.testing.assert_array_equal(report.hair.points, points[[0, 1, 2, 4, 5]])
    assert report.skipped_strands == 1


def test_ply_edges_must_join_consecutive_vertices():
    points, _ = strands_of([4])
    data = ply_bytes(
        "ascii",
        [
            ("vertex", 4, xyz_props(points)),
            ("edge", 2, [("vertex1", "int", [0, 1]), ("vertex2", "int", [1, 3])]),
        ],
    )
    err = expect_error("bad_index", read_hair_bytes, data, "ply")
    assert "consecutive" in str(err)


def test_ply_edges_disagreeing_with_strands():
    points, _ = strands_of([2, 2])
    data = ply_bytes(
        "ascii",
        [
            ("vertex", 4, xyz_props(points)),
            ("strand", 2, [("nsegs", "ushort", [1, 1])]),
            ("edge", 3, [("vertex1", "int", [0, 1, 2]), ("vertex2", "int", [1, 2, 3])]),
        ],
    )
    expect_error("bad_index", read_hair_bytes, data, "ply")


def test_ply_other_elements_and_properties_are_skipped():
    """A mesh in the same file (faces of varying size) and unknown properties."""
    points, offsets = strands_of([2, 3])
    props = xyz_props(points) + [("nx", "float", [0.0] * 5), ("quality", "double", [1.5] * 5)]
    faces = [[0, 1, 2], [1, 2, 3, 4]]
    data = ply_bytes(
        "binary_little_endian",
        [
            ("vertex", 5, props),
            (
                "face",
                2,
                [("vertex_indices", ("list", "uchar", "int"), faces), ("flag", "uchar", [1, 2])],
            ),
            ("strand", 2, [("nsegs", "ushort", [1, 2])]),
        ],
    )
    hair = read_hair_bytes(data, "ply")
    np.testing.assert_array_equal(hair.offsets, offsets)


@pytest.mark.parametrize("encoding", ["ascii", "binary_little_endian", "binary_big_endian"])
def test_ply_other_properties_become_attributes(encoding):
    points, _ = strands_of([2, 3])
    data = ply_bytes(
        encoding,
        [
            ("vertex", 5, xyz_props(points) + [("alpha", "uchar", [1, 2, 3, 4, 5]),
                                               ("uv_0", "float", [0.5, 1, 2, 3, 4]),
                                               ("uv_1", "float", [9, 8, 7, 6, 5])]),
            ("strand", 2, [("nsegs", "ushort", [1, 2]), ("group_id", "int", [7, -3])]),
        ],
    )
    report = read_hair_bytes_report(data, "ply")
    assert report.warnings == ()
    attributes = report.hair.attributes
    assert list(attributes) == ["alpha", "uv", "group_id"]
    assert attributes["alpha"].values.dtype == np.uint8 and attributes["alpha"].domain == "vertex"
    np.testing.assert_array_equal(attributes["alpha"].values, [1, 2, 3, 4, 5])
    np.testing.assert_array_equal(attributes["uv"].values, np.float32([[0.5, 9], [1, 8], [2, 7], [3, 6], [4, 5]]))
    assert attributes["group_id"].domain == "strand" and attributes["group_id"].values.dtype == np.int32
    np.testing.assert_array_equal(attributes["group_id"].values, [7, -3])


def test_ply_attributes_follow_the_vertex_order_of_index_lists():
    points, _ = strands_of([2, 2])
    data = ply_bytes(
        "ascii",
        [
            ("vertex", 4, xyz_props(points) + [("id", "int", [10, 11, 12, 13])]),
            ("strand", 2, [("vertex_indices", ("list", "uchar", "int"), [[2, 3], [0, 1]])]),
        ],
    )
    hair = read_hair_bytes(data, "ply")
    np.testing.assert_array_equal(hair.attributes["id"].values, [12, 13, 10, 11])
    np.testing.assert_array_equal(hair.points, points[[2, 3, 0, 1]])


@pytest.mark.parametrize("ascii", [False, True])
def test_ply_writes_attributes_back_as_read(ascii):
    hair = helix_hair(6)
    n, s = hair.n_particles, hair.n_strands
    rng = np.random.default_rng(3)
    attributes = {
        "uv": HairAttribute(rng.random((n, 2)).astype(np.float32), "vertex", "texcoord"),
        "weight": HairAttribute(rng.random(n), "vertex"),
        "clump": HairAttribute(rng.integers(0, 60000, n).astype(np.uint16), "vertex"),
        "group_id": HairAttribute(rng.integers(-5, 5, s).astype(np.int64), "strand"),
        "is_guide": HairAttribute(rng.random(s) < 0.5, "strand"),
    }
    hair = Hair(hair.points, hair.offsets, attributes=attributes)
    back = read_hair_bytes(hair_to_bytes(hair, "ply", ascii=ascii), "ply")
    assert list(back.attributes) == list(attributes)
    for name, attribute in attributes.items():
        np.testing.assert_array_equal(back.attributes[name].values, attribute.values)
        assert back.attributes[name].domain == attribute.domain
    # PLY has no 64-bit integers and no booleans: the nearest type that holds the values exactly
    assert back.attributes["group_id"].values.dtype == np.int32 and back.attributes["is_guide"].values.dtype == np.uint8


def test_ply_writer_drops_attributes_it_cannot_hold_and_says_which():
    hair = helix_hair(2)
    attributes = {
        "big": HairAttribute(np.array([1, 2**40]), "strand"),  # past int32
        "red": HairAttribute(np.zeros(hair.n_particles), "vertex"),  # the colour's property
        "kept": HairAttribute(np.arange(2, dtype=np.int64), "strand"),
    }
    with pytest.warns(HairIOWarning, match="'big', 'red'"):
        data = hair_to_bytes(Hair(hair.points, hair.offsets, attributes=attributes), "ply")
    assert list(read_hair_bytes(data, "ply").attributes) == ["kept"]


@pytest.mark.parametrize(
    "header",
    [
        ASCII_PLY + b"element vertex 1\n" + XYZ[:-17] + b"end_header\n1 2\n",  # no z
        ASCII_PLY + b"element vertex 2\n" + XYZ + b"end_header\n0 0 0 1 1 1\n",  # no strands
    ],
)
def test_ply_without_positions_or_strand_structure(header):
    err = expect_error("bad_header", read_hair_bytes, header, "ply", source="bad.ply")
    assert str(err).startswith("bad.ply: ")


def test_ply_nsegs_become_uint_above_65535_segments(tmp_path):
    write_hair(tmp_path / "long.ply", long_strand_hair(65_537))  # PLY switches nsegs to uint
    assert b"property uint nsegs" in (tmp_path / "long.ply").read_bytes()[:400]
    assert read_hair(tmp_path / "long.ply", limits=LONG_STRANDS).counts[0] == 65_537


def test_edge_starts_are_every_segment_first_vertex():
    starts = edge_starts(Hair(np.zeros((7, 3)), np.array([0, 3, 5, 7])))
    assert starts.dtype == np.dtype("<i4") and starts.tolist() == [0, 1, 3, 5]


def test_vertex_columns_in_file_units_with_8_bit_colors():
    hair = Hair(
        np.array([[0.5, 1.0, 1.5], [2.0, 2.5, 3.0]]),
        np.array([0, 2]),
        thickness=np.array([0.25, 0.5]),
        color=np.array([[0.0, 0.5, 1.0], [1.2, -0.1, 0.2]]),
    )
    columns = vertex_columns(hair, 0.5)
    assert [(name, kind) for name, kind, _ in columns] == [
        ("x", "float"), ("y", "float"), ("z", "float"), ("thickness", "float"),
        ("red", "uchar"), ("green", "uchar"), ("blue", "uchar"),
    ]  # fmt: skip
    values = {name: v for name, _, v in columns}
    np.testing.assert_array_equal(values["x"], np.float32([1, 4]))
    np.testing.assert_array_equal(values["z"], np.float32([3, 6]))
    np.testing.assert_array_equal(values["thickness"], np.float32([0.5, 1.0]))
    assert [values[c].tolist() for c in ("red", "green", "blue")] == [[0, 255], [128, 0], [255, 51]]


def test_counts_from_strand_ids_and_from_edges():
    assert counts_from_ids(np.array([5, 5, 2, 2, 2, 9]), "strand_id", CONTEXT).tolist() == [2, 3, 1]
    assert counts_from_ids(np.array([], dtype=np.int32), "strand_id", CONTEXT).tolist() == []
    err = expect_error("bad_index", counts_from_ids, np.array([1, 2, 1]), "curve_id", CONTEXT)
    assert "the vertices of one 'curve_id' are not consecutive" in str(err)
    edges = {"vertex1": np.array([5, 1, 0]), "vertex2": np.array([4, 2, 1])}
    assert counts_from_edges(edges, 6, CONTEXT).tolist() == [3, 1, 2]
    err = expect_error("bad_index", counts_from_edges, edges, 5, CONTEXT)
    assert "an edge refers to a vertex outside 0..4" in str(err)
