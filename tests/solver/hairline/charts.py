"""Head charts and scalp membranes of known geometry for the membrane, chart and Newton tests."""

import numpy as np

from hairport.solver.hairline.head_chart import HeadChart
from hairport.solver.hairline.membrane import Membrane
from tests.solver.triangle_grids import grid

PARABOLOID = 0.3  # head z = PARABOLOID (x^2 + y^2), uv = (x, y)


def paraboloid_chart(cells=16):
    uv, faces = grid(cells, cells, -1.0, 1.0, -1.0, 1.0)
    return HeadChart.build(np.column_stack([uv, PARABOLOID * (uv**2).sum(axis=1)]), faces, uv)


def flat_chart(cells=12):
    uv, faces = grid(cells, cells, -0.5, 1.5, -0.5, 1.5)
    return HeadChart.build(np.column_stack([uv, np.zeros(len(uv))]), faces, uv)


def rotated_scalp(chart, cells=6):
    """A small scalp grid, rotated and shifted so its vertices avoid the head's edges."""
    u, triangles = grid(cells, cells, -0.5, 0.5, -0.5, 0.5)
    c, s = np.cos(0.3), np.sin(0.3)
    u = u @ np.array([[c, s], [-s, c]]) + 0.013
    return Membrane.build(chart.embed(u), triangles), u


def boundary_of(u, low, high):
    return (np.isclose(u, low) | np.isclose(u, high)).any(axis=1)

