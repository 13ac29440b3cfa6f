"""The unit-square scalp of the relocation-baseline and density tests: a regular grid on
``[0, 1]^2`` laid flat or on a bowl, its outer ring as the hairline."""

import numpy as np
import pytest

from hairport.solver.model.errors import InputError
from tests.solver.triangle_grids import grid

CELLS = 8  # grid cells per side: (CELLS + 1)^2 vertices on [0, 1]^2
BOWL = 0.3  # curved scalp for the 3D RBF: z = BOWL (x^2 + y^2)


def square_grid(cells=CELLS):
    """Vertices ``((cells+1)^2, 2)`` of ``[0, 1]^2``, id ``i (cells+1) + j`` at ``(i, j) / cells``,
    and ``2 cells^2`` counter-clockwise triangles (diagonals from ``(i, j)`` to ``(i+1, j+1)``)."""
    return grid(cells, cells, 0.0, 1.0, 0.0, 1.0)


def outer_ring(points):
    return (np.isclose(points, 0.0) | np.isclose(points, 1.0)).any(axis=1)


def flat(points):
    return np.column_stack([points, np.zeros(len(points))])


def bowl(points):
    return np.column_stack([points, BOWL * (points**2).sum(axis=1)])


def expect_refusal(call, *args, **kwargs):
    with pytest.raises(InputError) as raised:
        call(*args, **kwargs)
    assert raised.value.code == "bad_relocation"
    return raised.value

