"""Input checks of the relocation baselines (Sec. 7.5) and Table 3's density change: id arrays,
triangles, points and pinned vertices; every refusal an :class:`InputError` with code
:data:`ERROR_CODE`."""

from __future__ import annotations

import numpy as np

from hairport.solver.model.errors import InputError

#: error code of every refusal of the relocation baselines and the density change
ERROR_CODE = "bad_relocation"


def refuse(problem: str, source: str) -> InputError:
    """The refusal to raise: ``problem`` reported by function ``source``, code :data:`ERROR_CODE`."""
    return InputError(problem, source, code=ERROR_CODE)


def index_array(values, ndim: int, what: str, source: str) -> np.ndarray:
    """Integer ids as int64.

    Parameters
    ----------
    values : array_like of int
    ndim : int
        1 (a list of ids) or 2 (triangles).
    what, source : str
        Names of the argument and of the function, for messages.

    Returns
    -------
    ids : int64 array with ``ndim`` dimensions
        An empty input gives ``(0,)`` (``ndim`` 1) or ``(0, 3)`` (``ndim`` 2).

    Raises
    ------
    InputError
        Non-integer dtype or another number of dimensions.
    """
    array = np.asarray(values)
    if array.size == 0:
        return np.zeros((0,) if ndim == 1 else (0, 3), dtype=np.int64)
    if array.dtype.kind not in "iu":
        raise refuse(f"{what} must be integer ids, got dtype {array.dtype}", source)
    if array.ndim != ndim:
        raise refuse(f"{what} must have {ndim} dimension(s), got shape {array.shape}", source)
    return array.astype(np.int64, copy=False)


def check_triangles(triangles, n: int, source: str) -> np.ndarray:
    """Triangles ``(m, 3) int64`` over vertices ``0 .. n - 1``.

    Raises
    ------
    InputError
        Not integer ids, not ``(m, 3)``, or ids outside ``0 .. n - 1``.
    """
    triangles = index_array(triangles, 2, "triangles", source)
    if triangles.shape[1] != 3:
        raise refuse(f"triangles must be (m, 3), got shape {triangles.shape}", source)
    if triangles.size and (triangles.min() < 0 or triangles.max() >= n):
        raise refuse(f"triangles index vertices outside 0 .. {n - 1}", source)
    return triangles


def check_points(points, dim: int, what: str, source: str) -> np.ndarray:
    """Finite points ``(n, dim) float64``.

    Raises
    ------
    InputError
        Another shape, or a non-finite coordinate.
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != dim:
        raise refuse(f"{what} must be (n, {dim}), got shape {points.shape}", source)
    if not np.isfinite(points).all():
        raise refuse(f"{what} has non-finite values", source)
    return points


def check_pins(fixed, targets, n: int, dim: int, source: str) -> tuple[np.ndarray, np.ndarray]:
    """Pinned vertices and their targets.

    Parameters
    ----------
    fixed : (n,) array_like of bool
    targets : (k, dim) array_like of float
        ``k = fixed.sum()``, in the order of ``np.flatnonzero(fixed)``; any empty array when
        ``k = 0``.
    n, dim : int
    source : str

    Returns
    -------
    fixed : (n,) bool
    targets : (k, dim) float64

    Raises
    ------
    InputError
        Wrong shapes or non-finite targets.
    """
    fixed = np.asarray(fixed)
    if fixed.shape != (n,):
        raise refuse(f"fixed must be ({n},), got shape {fixed.shape}", source)
    fixed = fixed.astype(bool)
    targets = np.asarray(targets, dtype=np.float64)
    k = int(fixed.sum())
    if k == 0 and targets.size == 0:
        targets = np.zeros((0, dim))
    if targets.shape != (k, dim):
        raise refuse(f"the {k} fixed vertices need targets ({k}, {dim}), got shape {targets.shape}", source)
    if not np.isfinite(targets).all():
        raise refuse("the fixed vertices' targets have non-finite values", source)
    return fixed, targets
