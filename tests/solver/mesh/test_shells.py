"""Shells, borders and non-manifold edges on hand-made meshes: a grid with a closed
tetrahedron beside it, a fin on one of its edges and a flipped face."""

import numpy as np
import pytest

from hairport.solver.mesh.shells import (
    MIN_ROOT_SHELL_SHARE,
    border_vertices,
    edge_distance,
    edge_table,
    explain_not_disk,
    manifold_face_adjacency,
    root_shell,
    shell_labels,
    shell_of,
    vertex_components,
)
from hairport.solver.model.errors import InputError
from tests.solver.triangle_grids import grid

#: a 4x4-cell grid on [0, 1]^2 in the z = 0 plane: vertex ``5 i + j`` at ``(i, j) / 4``; the
#: triangles of cell ``(i, j)`` are faces ``4 i + j`` and ``16 + 4 i + j``
POINTS_2D, GRID = grid(4, 4, 0.0, 1.0, 0.0, 1.0)
GRID_POINTS = np.column_stack([POINTS_2D, np.zeros(len(POINTS_2D))])
#: a closed tetrahedron (4 faces) on vertices 25-28, away from the grid
TETRA_POINTS = np.array([[2.0, 0.0, 0.0], [3.0, 0.0, 0.0], [2.0, 1.0, 0.0], [2.0, 0.0, 1.0]])
TETRA = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]]) + 25
POINTS = np.vstack([GRID_POINTS, TETRA_POINTS])
MESH = np.vstack([GRID, TETRA])


def cell(i, j):
    return np.array([4 * i + j, 16 + 4 * i + j])


def test_edge_table_counts_faces_per_edge_and_finds_the_border():
    edges = edge_table(GRID)
    # 4x4 cells: 40 axis edges and 16 diagonals; the border is 16 edges long
    assert len(edges.ends) == 56 and edges.border.sum() == 16 and edges.manifold.sum() == 40
    assert (edges.ends[:, 0] < edges.ends[:, 1]).all()
    assert np.array_equal(edges.ends[edges.of_half_edge], np.sort(GRID[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1))
    # a fin on the inner edge 6-7 (a third face there), a face flipped: neither is manifold
    fin = np.vstack([GRID, [[7, 6, 30]]])
    table = edge_table(fin)
    k = int(np.flatnonzero((table.ends == [6, 7]).all(axis=1))[0])
    assert table.count[k] == 3 and not table.manifold[k]
    flipped = GRID.copy()
    flipped[5] = flipped[5, ::-1]
    table = edge_table(flipped)
    assert table.manifold.sum() == 40 - 3  # its three inner edges join faces of one direction
    assert table.border.sum() == 16


def test_shells_are_joined_across_manifold_edges_only():
    labels = shell_labels(MESH)
    assert np.bincount(labels).tolist() == [32, 4]
    assert (labels[:32] == labels[0]).all() and (labels[32:] == labels[32]).all()
    adjacency = manifold_face_adjacency(MESH)
    assert adjacency.nnz == 2 * (40 + 6) and (adjacency != adjacency.T).nnz == 0
    # a fin and a flipped face fall apart from the grid; the grid stays one shell
    flipped = MESH.copy()
    flipped[5] = flipped[5, ::-1]
    with_fin = np.vstack([flipped, [[7, 6, 25]]])
    labels = shell_labels(with_fin)
    assert sorted(np.bincount(labels).tolist()) == [1, 1, 4, 31]
    assert labels[5] != labels[0] and labels[-1] != labels[0]
    seed = np.zeros(len(with_fin), dtype=bool)
    seed[0] = True
    assert shell_of(with_fin, seed).sum() == 31


def test_vertex_components_follow_the_edges():
    labels = vertex_components(MESH, len(POINTS) + 1)
    assert len(np.unique(labels)) == 3  # the grid, the tetrahedron, an unused vertex
    assert (labels[:25] == labels[0]).all() and (labels[25:29] == labels[25]).all() and labels[29] != labels[0]


def test_root_shell_is_the_one_with_most_roots():
    roots = np.concatenate([np.arange(32), [32, 33]])  # 32 roots on the grid, 2 on the tetrahedron
    shell = root_shell(MESH, roots)
    assert shell.sum() == 32 and shell[:32].all()
    assert 32 / 34 >= MIN_ROOT_SHELL_SHARE
    with pytest.raises(InputError, match="2 separate pieces of the mesh .20 on a piece of 32 faces, 4 on a piece "
                                         "of 4 faces") as refused:
        root_shell(MESH, np.concatenate([np.arange(20), [32, 33, 34, 35]]), "bust")
    assert refused.value.code == "roots_on_several_pieces" and refused.value.source == "bust"


def test_border_vertices_and_edge_distances():
    border = border_vertices(MESH, len(POINTS))
    assert border.sum() == 16 and not border[25:].any()
    assert not border[[6, 7, 8, 11, 12, 13, 16, 17, 18]].any()
    corner = np.zeros(len(POINTS), dtype=bool)
    corner[0] = True
    distance = edge_distance(POINTS, MESH, corner)
    # along the axes in steps of 1/4, or the diagonals of the cells (a, c): vertex 5 i + j
    assert distance[0] == 0 and distance[4] == pytest.approx(1.0) and distance[24] == pytest.approx(np.sqrt(2.0))
    assert distance[7] == pytest.approx(0.25 + np.sqrt(2.0) / 4)
    assert np.isinf(distance[25:]).all()
    assert np.isinf(edge_distance(POINTS, MESH, np.zeros(len(POINTS), dtype=bool))).all()


def test_a_region_around_a_gap_is_explained_as_a_hole():
    # the grid without cell (2, 2): a ring of the 8 cells around it is no disk
    holed = np.delete(GRID, cell(2, 2), axis=0)
    faces = np.vstack([holed, TETRA])
    shell = shell_labels(faces) == shell_labels(faces)[0]
    ring = [(i, j) for i in (1, 2, 3) for j in (1, 2, 3) if (i, j) != (2, 2)]
    region = np.zeros(len(faces), dtype=bool)
    for i, j in ring:
        region[np.flatnonzero((faces[:, None] == GRID[cell(i, j)][None]).all(axis=2).any(axis=1))] = True
    assert region.sum() == 16
    error = explain_not_disk(faces, region, shell, "scalp", POINTS, "bust")
    assert error.code == "mesh_hole" and error.source == "bust"
    assert "the scalp under the roots has a hole" in error.problem
    assert "4 border vertices near [0.625, 0.625, 0.0]" in error.problem


def test_a_region_with_a_non_manifold_edge_inside_is_explained():
    # a tent of three faces over the grid's triangle 6-7-12, on its three edges: each of
    # them is held by three faces
    sheet = np.array([[7, 6, 29], [6, 12, 29], [12, 7, 29]])
    faces = np.vstack([GRID, sheet])
    region = np.ones(len(faces), dtype=bool)
    shell = np.ones(len(faces), dtype=bool)
    error = explain_not_disk(faces, region, shell, "head patch")
    assert error.code == "not_manifold"
    assert "not manifold inside the head patch: 3 edges" in error.problem


def test_a_disk_or_a_ring_of_roots_is_not_the_mesh_s_fault():
    region = np.zeros(len(MESH), dtype=bool)
    region[:32] = True
    assert explain_not_disk(MESH, region, region, "scalp") is None
    # a ring of roots around cell (2, 2), which is there: no gap of the mesh inside
    ring = np.zeros(len(MESH), dtype=bool)
    for i in (1, 2, 3):
        for j in (1, 2, 3):
            ring[cell(i, j)] = (i, j) != (2, 2)
    assert explain_not_disk(MESH, ring, region, "scalp") is None
