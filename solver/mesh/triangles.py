"""Per-triangle quantities: barycentric coordinates and interpolation, tangent frames.

Convention: ``vertices (V, 3) float64``, ``faces (F, 3) int64``; arguments in the order ``(vertices, faces, ...)``.
"""

from __future__ import annotations

import numpy as np


def barycentric_coordinates(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Barycentric coordinates of points with respect to triangles (of the projection onto the plane).

    Parameters
    ----------
    points : (N, 3) float64
    triangles : (N, 3, 3) float64
        Corner positions, one triangle per point.

    Returns
    -------
    barycentric : (N, 3) float64
        Sums to 1 per row.
    """
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    v0, v1, v2 = b - a, c - a, points - a
    d00 = np.einsum("ij,ij->i", v0, v0)
    d01 = np.einsum("ij,ij->i", v0, v1)
    d11 = np.einsum("ij,ij->i", v1, v1)
    d20 = np.einsum("ij,ij->i", v2, v0)
    d21 = np.einsum("ij,ij->i", v2, v1)
    denom = d00 * d11 - d01 * d01
    denom = np.where(np.abs(denom) > 0, denom, 1.0)
    v = (d11 * d20 - d01 * d21) / denom
    w = (d00 * d21 - d01 * d20) / denom
    return np.stack([1.0 - v - w, v, w], axis=1)


def interpolate_barycentric(vertices: np.ndarray, faces: np.ndarray, face_ids: np.ndarray, barycentric: np.ndarray) -> np.ndarray:
    """Points given by face and barycentric coordinates.

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    face_ids : (N,) int64
    barycentric : (N, 3) float64

    Returns
    -------
    points : (N, 3) float64
    """
    corners = vertices[faces[face_ids]]
    return np.einsum("ij,ijk->ik", barycentric, corners)


#: faces whose normal or first edge is shorter than this (m) have no frame (identity)
DEGENERATE_FACE_LENGTH = 1e-15


def face_frames(vertices: np.ndarray, faces: np.ndarray, face_ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal frames of faces: columns (normal, first edge direction, their cross product).

    Parameters
    ----------
    vertices : (V, 3) float64
    faces : (F, 3) int64
    face_ids : (K,) int64

    Returns
    -------
    frames : (K, 3, 3) float64
        ``frames[k] = [n | t | n x t]`` as columns; a rotation matrix (det +1).
    valid : (K,) bool
        False for degenerate faces (their frame is the identity).
    """
    corners = vertices[faces[face_ids]]
    edge1 = corners[:, 1] - corners[:, 0]
    edge2 = corners[:, 2] - corners[:, 0]
    normal = np.cross(edge1, edge2)
    normal_len = np.linalg.norm(normal, axis=1)
    valid = normal_len > DEGENERATE_FACE_LENGTH
    normal = normal / np.where(valid, normal_len, 1.0)[:, None]
    # the first edge lies in the face plane, so it is already orthogonal to the normal;
    # Gram-Schmidt removes the round-off component
    tangent = edge1 - np.einsum("ij,ij->i", edge1, normal)[:, None] * normal
    tangent_len = np.linalg.norm(tangent, axis=1)
    valid &= tangent_len > DEGENERATE_FACE_LENGTH
    tangent = tangent / np.where(valid, tangent_len, 1.0)[:, None]
    frames = np.stack([normal, tangent, np.cross(normal, tangent)], axis=2)
    frames[~valid] = np.eye(3)
    return frames, valid
