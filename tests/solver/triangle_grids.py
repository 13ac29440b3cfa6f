"""Regular triangle grids for mesh and hairline tests."""

import numpy as np


def grid(nx, ny, x0, x1, y0, y1):
    """Vertices ``((nx+1)(ny+1), 2)`` and ``2 nx ny`` counter-clockwise triangles of a grid."""
    xs, ys = np.meshgrid(np.linspace(x0, x1, nx + 1), np.linspace(y0, y1, ny + 1), indexing="ij")
    points = np.column_stack([xs.ravel(), ys.ravel()])
    index = np.arange((nx + 1) * (ny + 1)).reshape(nx + 1, ny + 1)
    a, b, c, d = index[:-1, :-1].ravel(), index[1:, :-1].ravel(), index[1:, 1:].ravel(), index[:-1, 1:].ravel()
    return points, np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])])
