"""Triangle areas: signed areas of planar (2D) triangles and areas of triangles in 3D.

One argument order everywhere, ``(points, triangles)``, as gpytoolbox's ``doublearea(V, F)``.
"""

from __future__ import annotations

import numpy as np


def signed_areas(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Signed areas of planar triangles, positive where the corners run counter-clockwise.

    Parameters
    ----------
    points : (n, 2) float64
        Vertex positions in the plane (e.g. uv parameters).
    triangles : (m, 3) int64
        Vertex ids of each triangle's corners.

    Returns
    -------
    areas : (m,) float64
        In units of ``points`` squared.
    """
    corners = np.asarray(points, dtype=np.float64)[triangles]
    e1 = corners[:, 1] - corners[:, 0]
    e2 = corners[:, 2] - corners[:, 0]
    return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


def triangle_areas(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Areas of triangles in space (half the norm of the edge cross product).

    Parameters
    ----------
    points : (n, 3) float64
        Vertex positions (e.g. meters).
    triangles : (m, 3) int64
        Vertex ids of each triangle's corners.

    Returns
    -------
    areas : (m,) float64
        Non-negative, in units of ``points`` squared.
    """
    corners = np.asarray(points, dtype=np.float64)[triangles]
    return 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
