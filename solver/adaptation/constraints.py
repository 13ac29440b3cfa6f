"""Eq. 12-13: roots fixed, every other particle kept ``eps_c`` outside the target body."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hairport.solver.mesh.query import MeshQuery


class BodyDistance:
    """Signed distance to the target for the particles that can be near it.

    Without a broad phase every particle gets an exact query. With one (a function giving a
    lower bound of ``|distance|`` per point), particles whose bound exceeds ``band`` get that
    bound as their distance, a zero normal and no constraint.
    """

    def __init__(self, query: MeshQuery, band: float = np.inf, broad_phase: Callable[[np.ndarray], np.ndarray] | None = None):
        self.query = query
        self.band = band
        self.broad_phase = broad_phase

    def __call__(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``points (N, 3)`` -> distance ``(N,)``, normal ``(N, 3)``, near ``(N,) bool``."""
        n = len(points)
        if self.broad_phase is None:
            sd = self.query.signed_distance(points)
            return sd.distance, sd.normal, np.ones(n, dtype=bool)
        near = self.broad_phase(points) < self.band
        distance = np.full(n, np.inf)
        normal = np.zeros((n, 3))
        if near.any():
            sd = self.query.signed_distance(points[near])
            distance[near] = sd.distance
            normal[near] = sd.normal
        return distance, normal, near
