"""The skin of a glTF mesh: its joints as a skeleton of bones, and its skin weights.

Bone ``b`` is joint ``b`` of the skin, named after its node (made unique by a ``_<b>``
suffix where names repeat, :func:`~hairport.solver.io.character.bones.unique_names`). Its head
is the joint's bind-pose position in mesh space, the translation of the inverse of its inverse
bind matrix (the node hierarchy's world transform when the skin has no inverse bind matrices).
Its parent is the nearest ancestor node that is a joint of the skin. Its tail follows the
convention of :mod:`~hairport.solver.io.character.bones` (the mean head of its child joints;
leaves and isolated joints as described there). Weights come from the ``JOINTS_n`` /
``WEIGHTS_n`` attribute sets of the primitives.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from hairport.solver.io.character.bones import bone_tails, unique_names
from hairport.solver.io.character.gltf.buffers import GltfReader
from hairport.solver.io.character.mesh_file import MAX_BONES, Skin
from hairport.solver.model.character import Skeleton, normalise_weight_rows
from hairport.solver.model.errors import InputError


def read_gltf_skin(
    reader: GltfReader,
    skin_index: int,
    primitives: list,
    counts: list[int],
    vertices: np.ndarray,
    world: np.ndarray,
    source: str,
) -> Skin:
    """The skeleton and weights of skin ``skin_index`` (see the module docstring).

    Parameters
    ----------
    reader : GltfReader
    skin_index : int
    primitives : list of dict
        The primitives of the skinned mesh, in the order their vertices were concatenated.
    counts : list of int
        Vertex count of each primitive.
    vertices : (V, 3) float64
        The mesh's vertices (their bounding box sizes the bones without a direction).
    world : (N, 4, 4) float64
        World transform of every node.
    source : str
        The file, for errors.

    Returns
    -------
    skin : Skin
        In file units.
    """
    skin = reader.item("skins", skin_index)
    joints = np.asarray(skin.get("joints", []), dtype=np.int64)
    nodes = reader.document.get("nodes", [])
    n_bones = len(joints)
    if n_bones == 0:
        raise InputError(f"skin {skin_index} has no joints", source, "bad_skeleton")
    if n_bones > MAX_BONES:
        raise InputError(f"skin has {n_bones} joints, more than {MAX_BONES}", source, "too_large")
    if joints.min() < 0 or joints.max() >= len(nodes) or len(np.unique(joints)) != n_bones:
        raise InputError(f"skin {skin_index} has an invalid or repeated joint node", source, "bad_skeleton")
    bind = _bind_matrices(reader, skin, joints, world, source)
    heads = bind[:, :3, 3]
    parents = _joint_parents(reader.parents(), joints)
    diagonal = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0))) or 1.0
    tails = bone_tails(heads, parents, bind, diagonal)
    raw_names = [str(nodes[j].get("name") or f"joint_{b}") for b, j in enumerate(joints.tolist())]
    skeleton = Skeleton(unique_names(raw_names), parents, heads, tails)
    weights = _skin_weights(reader, primitives, counts, len(vertices), n_bones, source)
    return Skin(skeleton, weights)


def _bind_matrices(reader: GltfReader, skin: dict, joints: np.ndarray, world: np.ndarray, source: str) -> np.ndarray:
    """(B, 4, 4) bind-pose transform of every joint: the inverse of its inverse bind matrix,
    else the node's world transform."""
    n_bones = len(joints)
    if "inverseBindMatrices" not in skin:
        return world[joints]
    inverse_bind = reader.accessor(skin["inverseBindMatrices"]).astype(np.float64)
    if inverse_bind.shape != (n_bones, 16):
        raise InputError("inverse bind matrices do not match the joint count", source, "bad_skeleton")
    inverse_bind = inverse_bind.reshape(n_bones, 4, 4).transpose(0, 2, 1)  # column-major
    if not np.isfinite(inverse_bind).all():
        raise InputError("inverse bind matrices are not finite", source, "non_finite")
    try:
        return np.linalg.inv(inverse_bind)
    except np.linalg.LinAlgError:
        raise InputError("an inverse bind matrix is singular", source, "bad_skeleton") from None


def _joint_parents(node_parents: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """(B,) int64 parent bone of every joint: its nearest ancestor node that is a joint, else -1.

    Parameters
    ----------
    node_parents : (N,) int64
        Parent node of every node, -1 for a root.
    joints : (B,) int64
        The node of every joint.
    """
    n_nodes, n_bones = len(node_parents), len(joints)
    bone_of_node = np.full(n_nodes + 1, -1, dtype=np.int64)
    bone_of_node[joints] = np.arange(n_bones)
    parents = np.full(n_bones, -1, dtype=np.int64)
    ancestor = node_parents[joints]
    open_ = ancestor >= 0
    for _ in range(n_nodes):
        if not open_.any():
            break
        found = open_ & (bone_of_node[ancestor] >= 0)
        parents[found] = bone_of_node[ancestor[found]]
        open_ &= ~found
        ancestor = np.where(open_, node_parents[np.maximum(ancestor, 0)], -1)
        open_ &= ancestor >= 0
    return parents


def _skin_weights(
    reader: GltfReader, primitives: list, counts: list[int], n_vertices: int, n_bones: int, source: str
) -> sp.csr_matrix:
    """(V, B) weights from every ``JOINTS_n`` / ``WEIGHTS_n`` pair of the primitives, rows normalised."""
    rows, cols, vals = [], [], []
    offset = 0
    for primitive, count in zip(primitives, counts):
        attributes = primitive.get("attributes", {})
        set_index = 0
        while f"JOINTS_{set_index}" in attributes and f"WEIGHTS_{set_index}" in attributes:
            joint_ids = reader.accessor(attributes[f"JOINTS_{set_index}"]).astype(np.int64)
            weight = reader.accessor(attributes[f"WEIGHTS_{set_index}"]).astype(np.float64)
            if joint_ids.shape != weight.shape or len(joint_ids) != count:
                raise InputError(
                    f"JOINTS_{set_index}/WEIGHTS_{set_index} do not match the vertex count", source, "bad_weights"
                )
            if not np.isfinite(weight).all() or (weight < 0).any():
                raise InputError(f"WEIGHTS_{set_index} has a negative or non-finite weight", source, "bad_weights")
            used = weight > 0
            if used.any() and (joint_ids[used].min() < 0 or joint_ids[used].max() >= n_bones):
                raise InputError(f"JOINTS_{set_index} refers to a joint outside the skin", source, "bad_weights")
            rows.append((np.arange(count)[:, None] + offset + np.zeros_like(joint_ids))[used])
            cols.append(joint_ids[used])
            vals.append(weight[used])
            set_index += 1
        offset += count
    if rows:
        weights = sp.csr_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(n_vertices, n_bones)
        )
    else:
        weights = sp.csr_matrix((n_vertices, n_bones))
    return normalise_weight_rows(weights)
