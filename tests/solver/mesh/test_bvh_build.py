"""The compiled tree build: every face in exactly one leaf, every node's box around its faces."""

import numpy as np

from hairport.solver.mesh.bvh_build import build_nodes
from tests.solver.mesh.meshes import icosphere


def test_every_face_sits_in_one_leaf_inside_its_box():
    vertices, faces = icosphere(subdivisions=3)
    corners = vertices[faces]
    lower, upper = corners.min(axis=1), corners.max(axis=1)
    boxes, child, first, count, order = build_nodes(corners.mean(axis=1), lower, upper, 4)
    leaves = np.flatnonzero((child < 0) & (count > 0))
    assert 0 < len(leaves) and np.all(count[leaves] <= 4)
    in_leaves = np.concatenate([order[first[leaf]:first[leaf] + count[leaf]] for leaf in leaves])
    np.testing.assert_array_equal(np.sort(in_leaves), np.arange(len(faces)))
    for leaf in leaves:
        held = order[first[leaf]:first[leaf] + count[leaf]]
        assert np.all(boxes[leaf, :3] <= lower[held].min(axis=0)) and np.all(boxes[leaf, 3:] >= upper[held].max(axis=0))
    # the root's box is the mesh's
    np.testing.assert_allclose(boxes[0, :3], lower.min(axis=0))
    np.testing.assert_allclose(boxes[0, 3:], upper.max(axis=0))
