"""Mesh topology on hand-checked meshes: edges, adjacency, the edge graph's Laplacian, boundary
loops, disks, hole filling and subdivision."""

import numpy as np
import pytest

from hairport.solver.mesh.topology import (
    boundary_edges,
    boundary_loops,
    check_disk,
    corner_neighbours,
    euler_characteristic,
    face_adjacency,
    fill_holes,
    graph_laplacian,
    half_edges,
    is_disk,
    largest_piece,
    make_disk,
    repair_disk,
    subdivide,
    submesh,
    vertex_adjacency,
    vertex_faces,
)
from hairport.solver.model.errors import InputError
from tests.solver.triangle_grids import grid

#: the 2x2-cell grid on [0, 1]^2: vertex ``3 i + j`` at ``(i, j) / 2``, 8 counter-clockwise triangles
POINTS, SQUARE = grid(2, 2, 0.0, 1.0, 0.0, 1.0)
#: its undirected edges, by hand: 12 along the axes, 4 diagonals
SQUARE_EDGES = [(0, 1), (1, 2), (3, 4), (4, 5), (6, 7), (7, 8), (0, 3), (3, 6), (1, 4), (4, 7), (2, 5), (5, 8),
                (0, 4), (1, 5), (3, 7), (4, 8)]
#: a closed surface: a tetrahedron, outward-facing
TETRAHEDRON = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])


def cell_faces(cells, n=5):
    """Face ids of cells ``(i, j)`` of ``grid(n, n, ...)``: its two triangles per cell."""
    index = np.array([i * n + j for i, j in cells])
    return np.sort(np.concatenate([index, n * n + index]))


def test_the_square_grid_is_as_documented():
    np.testing.assert_array_equal(SQUARE, [[0, 3, 4], [1, 4, 5], [3, 6, 7], [4, 7, 8],
                                           [0, 4, 1], [1, 5, 2], [3, 7, 4], [4, 8, 5]])


def test_half_edges_run_corner_to_corner_face_by_face():
    edges = half_edges(SQUARE)
    assert edges.shape == (24, 2) and edges.dtype == np.int64
    np.testing.assert_array_equal(edges[:3], [[0, 3], [3, 4], [4, 0]])
    np.testing.assert_array_equal(edges[21:], [[4, 8], [8, 5], [5, 4]])
    assert half_edges([[2, 1, 0]]).tolist() == [[2, 1], [1, 0], [0, 2]]


def test_vertex_adjacency_is_the_edge_graph():
    adjacency = vertex_adjacency(SQUARE, 10)  # vertex 9 in no face
    expected = np.zeros((10, 10), dtype=bool)
    for a, b in SQUARE_EDGES:
        expected[a, b] = expected[b, a] = True
    assert adjacency.dtype == bool
    np.testing.assert_array_equal(adjacency.toarray(), expected)
    assert adjacency.nnz == 2 * len(SQUARE_EDGES)


def test_graph_laplacian_by_hand():
    laplacian = graph_laplacian(SQUARE, 9)
    expected = np.zeros((9, 9))
    for a, b in SQUARE_EDGES:
        expected[a, b] = expected[b, a] = -1.0
    expected[np.diag_indices(9)] = -expected.sum(axis=1)
    np.testing.assert_array_equal(laplacian.toarray(), expected)
    assert laplacian[4, 4] == 6.0 and laplacian[0, 0] == 3.0 and laplacian[2, 2] == 2.0
    # the centre's six neighbours are symmetric about it: affine fields are harmonic there
    field = POINTS @ np.array([[0.3, -1.2], [2.0, 0.7]]) + [0.25, -4.0]
    np.testing.assert_allclose((laplacian @ field)[4], [0.0, 0.0], rtol=0, atol=1e-14)


def test_face_adjacency_pairs_faces_across_interior_edges():
    adjacency = face_adjacency(SQUARE)
    # each diagonal joins its cell's two triangles; each inner axis edge two cells' triangles
    expected = {(0, 4), (1, 5), (2, 6), (3, 7), (0, 6), (1, 7), (4, 1), (6, 3)}
    pairs = {tuple(sorted(pair)) for pair in zip(*adjacency.nonzero())}
    assert pairs == {tuple(sorted(pair)) for pair in expected}
    assert adjacency.nnz == 16 and (adjacency != adjacency.T).nnz == 0
    # a non-manifold edge (0, 1) with three faces: chained in face order, 0-1 and 1-2
    fan = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4]])
    assert {tuple(pair) for pair in zip(*face_adjacency(fan).nonzero())} == {(0, 1), (1, 0), (1, 2), (2, 1)}


def test_corner_neighbours_by_hand():
    neighbours = corner_neighbours(SQUARE)
    assert neighbours.shape == (8, 3) and neighbours.dtype == np.int64
    # face 0 = (0, 3, 4): across 3-4 is face 6, across 4-0 face 4, 0-3 is on the border
    np.testing.assert_array_equal(neighbours[0], [6, 4, -1])
    # face 4 = (0, 4, 1): across 4-1 face 1, 1-0 on the border, across 0-4 face 0
    np.testing.assert_array_equal(neighbours[4], [1, -1, 0])
    # symmetric: f is across from each of its neighbours
    for f, row in enumerate(neighbours):
        for g in row[row >= 0]:
            assert f in neighbours[g]
    assert (neighbours >= 0).sum() == 16
    np.testing.assert_array_equal(corner_neighbours(TETRAHEDRON) >= 0, np.ones((4, 3), dtype=bool))


def test_vertex_faces_by_hand():
    start, faces, corners = vertex_faces(SQUARE, 10)
    assert start.shape == (11,) and start[-1] == 24 and start[9] == start[10] == 24
    np.testing.assert_array_equal(np.diff(start), [2, 3, 1, 3, 6, 3, 1, 3, 2, 0])
    around = slice(start[4], start[5])
    np.testing.assert_array_equal(faces[around], [0, 1, 3, 4, 6, 7])
    np.testing.assert_array_equal(corners[around], [2, 1, 0, 1, 2, 0])
    np.testing.assert_array_equal(SQUARE[faces, corners], np.repeat(np.arange(10), np.diff(start)))


def test_submesh_renumbers_the_chosen_faces():
    vertices, triangles = submesh(SQUARE, np.array([3, 7]))
    np.testing.assert_array_equal(vertices, [4, 5, 7, 8])
    np.testing.assert_array_equal(triangles, [[0, 2, 3], [0, 3, 1]])
    np.testing.assert_array_equal(vertices[triangles], SQUARE[[3, 7]])


def test_euler_characteristic():
    assert euler_characteristic(SQUARE) == 9 - 16 + 8 == 1
    assert euler_characteristic(TETRAHEDRON) == 2
    # two faces sharing a vertex only: 1 like a disk (check_disk also counts boundary loops)
    assert euler_characteristic(SQUARE[[0, 3]]) == 5 - 6 + 2 == 1
    assert euler_characteristic(np.zeros((0, 3), np.int64)) == 0


def test_boundary_loops_and_edges_of_the_square():
    loops = boundary_loops(SQUARE)
    assert len(loops) == 1
    np.testing.assert_array_equal(loops[0], [0, 3, 6, 7, 8, 5, 2, 1])  # counter-clockwise from vertex 0
    np.testing.assert_array_equal(check_disk(SQUARE), loops[0])
    on_border = boundary_edges(SQUARE, 9)
    np.testing.assert_array_equal(on_border[0], [True, False, False])  # 0-3 of face (0, 3, 4)
    np.testing.assert_array_equal(on_border[5], [False, True, True])  # 5-2 and 2-1 of face (1, 5, 2)
    assert on_border.sum() == 8
    assert boundary_loops(TETRAHEDRON) == [] and boundary_loops(np.zeros((0, 3), np.int64)) == []


def test_boundary_loops_longest_first():
    # the 4x4 grid without the six faces around its centre vertex 12: an annulus
    points, faces = grid(4, 4, 0.0, 1.0, 0.0, 1.0)
    annulus = faces[~(faces == 12).any(axis=1)]
    loops = boundary_loops(annulus)
    assert [len(loop) for loop in loops] == [16, 6]
    assert sorted(loops[1].tolist()) == [6, 7, 11, 13, 17, 18]
    with pytest.raises(InputError, match="2 boundary loops and Euler characteristic 0") as caught:
        check_disk(annulus, "ring")
    assert caught.value.code == "not_a_disk" and "the ring is not a disk" in str(caught.value)


@pytest.mark.parametrize("triangles, message", [
    ([[0, 1, 2], [0, 1, 3]], "not consistently oriented"),
    ([[0, 1, 2], [0, 3, 4]], "touches itself"),
])
def test_boundary_loops_refuse_bad_regions(triangles, message):
    with pytest.raises(InputError, match=message) as caught:
        boundary_loops(np.array(triangles))
    assert caught.value.code == "not_a_disk"


def test_check_disk_refuses_a_closed_surface():
    with pytest.raises(InputError, match="0 boundary loops and Euler characteristic 2"):
        check_disk(TETRAHEDRON)


def ring_with_hole():
    """grid(6) faces: a band of cells around the centre vertex (3, 3) minus its six faces, and those six."""
    points, faces = grid(6, 6, 0.0, 6.0, 0.0, 6.0)
    centroid = points[faces].mean(axis=1)
    inner = ((centroid > 1.0) & (centroid < 5.0)).all(axis=1)
    hole = (faces == 3 * 7 + 3).any(axis=1)
    return faces, inner & ~hole, hole


def test_fill_holes_fills_what_the_body_does_not_reach():
    faces, region, hole = ring_with_hole()
    assert (region.sum(), hole.sum()) == (32 - 6, 6)
    adjacency = face_adjacency(faces)
    np.testing.assert_array_equal(fill_holes(region, adjacency), region | hole)
    np.testing.assert_array_equal(fill_holes(region | hole, adjacency), region | hole)
    everything = np.ones(len(faces), dtype=bool)
    np.testing.assert_array_equal(fill_holes(everything, adjacency), everything)


def test_largest_piece_goes_by_weight():
    _, faces = grid(5, 5, 0.0, 1.0, 0.0, 1.0)
    adjacency = face_adjacency(faces)
    region = np.zeros(len(faces), dtype=bool)
    small, large = cell_faces([(0, 0)]), cell_faces([(3, 3), (3, 4), (4, 3), (4, 4)])
    region[small] = region[large] = True
    weight = np.ones(len(faces))
    np.testing.assert_array_equal(np.flatnonzero(largest_piece(region, adjacency, weight)), large)
    weight[small] = 10.0  # 20 > 8
    np.testing.assert_array_equal(np.flatnonzero(largest_piece(region, adjacency, weight)), small)
    # ties go to the piece with more faces
    np.testing.assert_array_equal(np.flatnonzero(largest_piece(region, adjacency, np.zeros(len(faces)))), large)


def test_make_disk_keeps_the_heaviest_piece_and_fills_its_hole():
    _, faces = grid(5, 5, 0.0, 1.0, 0.0, 1.0)
    adjacency = face_adjacency(faces)
    ring = [(1, 1), (2, 1), (3, 1), (3, 2), (3, 3), (2, 3), (1, 3), (1, 2)]  # around cell (2, 2)
    region = np.zeros(len(faces), dtype=bool)
    region[cell_faces(ring)] = True
    region[cell_faces([(4, 0)])] = True  # a stray piece touching the ring at a vertex only
    disk = make_disk(faces, region, adjacency, region.astype(float), "test region")
    np.testing.assert_array_equal(np.flatnonzero(disk), cell_faces(ring + [(2, 2)]))
    with pytest.raises(InputError, match="the test region is empty") as caught:
        make_disk(faces, np.zeros(len(faces), dtype=bool), adjacency, np.ones(len(faces)), "test region")
    assert caught.value.code == "not_a_disk"


def test_repair_disk_returns_what_it_could_not_make_a_disk():
    # the grid with cell (2, 2) gone from the mesh: a ring around it stays a ring (no faces
    # to fill the hole with); make_disk refuses it, repair_disk hands it back unchecked
    _, full = grid(5, 5, 0.0, 1.0, 0.0, 1.0)
    faces = np.delete(full, cell_faces([(2, 2)]), axis=0)
    ring = [(1, 1), (2, 1), (3, 1), (3, 2), (3, 3), (2, 3), (1, 3), (1, 2)]
    region = (faces[:, None] == full[cell_faces(ring)][None]).all(axis=2).any(axis=1)
    assert region.sum() == 16
    adjacency = face_adjacency(faces)
    repaired = repair_disk(faces, region, adjacency, region.astype(float), "ring")
    np.testing.assert_array_equal(repaired, region)
    assert not is_disk(submesh(faces, np.flatnonzero(repaired))[1])
    with pytest.raises(InputError, match="the ring is not a disk: 2 boundary loops and Euler characteristic 0"):
        make_disk(faces, region, adjacency, region.astype(float), "ring")
    assert is_disk(full) and not is_disk(TETRAHEDRON) and not is_disk(np.zeros((0, 3), np.int64))


def test_subdivide_one_triangle():
    points = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    new_points, triangles, loop = subdivide(points, np.array([[0, 1, 2]]), np.array([0, 1, 2]))
    np.testing.assert_array_equal(new_points[3:], [[0.5, 0.0], [0.0, 0.5], [0.5, 0.5]])  # edges 0-1, 0-2, 1-2
    np.testing.assert_array_equal(triangles, [[0, 3, 4], [3, 1, 5], [4, 5, 2], [3, 5, 4]])
    np.testing.assert_array_equal(loop, [0, 3, 1, 5, 2, 4])


def test_subdivide_the_square_keeps_a_disk():
    new_points, triangles, loop = subdivide(POINTS, SQUARE, boundary_loops(SQUARE)[0])
    assert (len(new_points), len(triangles), len(loop)) == (9 + 16, 32, 16)
    assert euler_characteristic(triangles) == 1
    np.testing.assert_array_equal(boundary_loops(triangles)[0], loop)
    np.testing.assert_array_equal(loop[::2], boundary_loops(SQUARE)[0])
