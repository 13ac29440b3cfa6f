"""A capsule-like closed body and a three-bone chain inside it, shared by the character tests.

The surface is a surface of revolution around z: ``n_rings`` rings of ``n_around`` vertices
between two pole vertices, radius ``r(t) = radius (1 - |t|^6)^(1/6)`` at height
``half_height t``, ``t`` in (-1, 1); faces are outward (counter-clockwise from outside).
"""

from __future__ import annotations

import numpy as np

from hairport.solver.model.character import Skeleton

#: default size of the body (m)
BODY_RADIUS = 0.15
BODY_HALF_HEIGHT = 0.75

#: a bone chain along z through the body: pelvis -> spine -> head (m)
CHAIN_NAMES = ("pelvis", "spine", "head")
CHAIN_PARENTS = (-1, 0, 1)
CHAIN_HEADS = ((0.0, 0.0, -0.5), (0.0, 0.0, -0.1), (0.0, 0.0, 0.3))
CHAIN_TAILS = ((0.0, 0.0, -0.1), (0.0, 0.0, 0.3), (0.0, 0.0, 0.6))


def capsule(n_rings: int, n_around: int, radius: float = BODY_RADIUS, half_height: float = BODY_HALF_HEIGHT):
    """The capsule as polygons.

    Returns
    -------
    vertices : (2 + n_rings * n_around, 3) float64
        Bottom pole, the rings bottom up, top pole.
    quads : ((n_rings - 1) * n_around, 4) int64
        ``(a, b, c, d)`` joining ring ``k`` (``a``, ``b``) to ring ``k + 1`` (``c``, ``d``).
    bottom, top : (n_around, 3) int64
        The triangle fans closing the ends at the poles.
    """
    t = np.linspace(-1.0, 1.0, n_rings + 2)[1:-1]
    r = radius * (1.0 - np.abs(t) ** 6) ** (1.0 / 6.0)
    theta = 2.0 * np.pi * np.arange(n_around) / n_around
    rings = np.stack(
        [np.outer(r, np.cos(theta)), np.outer(r, np.sin(theta)), np.repeat(half_height * t[:, None], n_around, 1)],
        axis=2,
    ).reshape(-1, 3)
    vertices = np.concatenate([[[0.0, 0.0, -half_height]], rings, [[0.0, 0.0, half_height]]])
    pole = len(vertices) - 1

    def ring(k, i):
        return 1 + k * n_around + (i % n_around)

    k, i = np.meshgrid(np.arange(n_rings - 1), np.arange(n_around), indexing="ij")
    k, i = k.ravel(), i.ravel()
    quads = np.stack([ring(k, i), ring(k, i + 1), ring(k + 1, i + 1), ring(k + 1, i)], 1).astype(np.int64)
    i = np.arange(n_around)
    bottom = np.stack([np.zeros(n_around, np.int64), ring(0, i + 1), ring(0, i)], 1).astype(np.int64)
    top = np.stack([np.full(n_around, pole), ring(n_rings - 1, i), ring(n_rings - 1, i + 1)], 1).astype(np.int64)
    return vertices, quads, bottom, top


def capsule_mesh(n_rings: int, n_around: int, radius: float = BODY_RADIUS, half_height: float = BODY_HALF_HEIGHT):
    """The capsule as triangles: every quad ``(a, b, c, d)`` split into ``(a, b, c)`` and ``(a, c, d)``.

    Returns
    -------
    vertices : (2 + n_rings * n_around, 3) float64
    faces : (F, 3) int64
        The bottom fan, the first triangle of every quad, the second of every quad, the top fan.
    """
    vertices, quads, bottom, top = capsule(n_rings, n_around, radius, half_height)
    return vertices, np.concatenate([bottom, quads[:, [0, 1, 2]], quads[:, [0, 2, 3]], top])


def chain_skeleton(offset_x: float = 0.0) -> Skeleton:
    """The pelvis -> spine -> head chain, shifted by ``offset_x`` along x."""
    shift = np.array([offset_x, 0.0, 0.0])
    return Skeleton(CHAIN_NAMES, CHAIN_PARENTS, np.add(CHAIN_HEADS, shift), np.add(CHAIN_TAILS, shift))
