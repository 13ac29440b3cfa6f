"""Table 3's root density change: roots per scalp triangle area before and after a relocation.

Per scalp triangle, the roots in it divided by its area, before and after the relocation; the
relative changes of the triangles holding roots form a vector whose mean absolute value (L1)
and largest absolute value (L-infinity) are reported. Roots keep their triangle (barycentric
coordinates), so a triangle's relative change is ``A / A' - 1`` with ``A``, ``A'`` its rest and
deformed 3D areas, whatever its root count. Bad input raises :class:`~hairport.solver.model.errors.InputError` with
``code="bad_relocation"`` (:mod:`.checks`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hairport.solver.hairline.checks import check_points, check_triangles, index_array, refuse
from hairport.solver.mesh.areas import triangle_areas


@dataclass(frozen=True, eq=False)
class DensityChange:
    """Relative change of the hair-root density per scalp triangle (Table 3).

    Attributes
    ----------
    l1 : float
        Mean of ``|changes|`` (0.0 when no triangle holds a root).
    linf : float
        Largest ``|changes|`` (0.0 when no triangle holds a root).
    changes : (t,) float64
        ``A / A' - 1`` per triangle holding roots (rest over deformed 3D area); ``inf`` for
        a triangle collapsed to zero area.
    triangles : (t,) int64
        The triangles holding roots, ascending ids.
    """

    l1: float
    linf: float
    changes: np.ndarray
    triangles: np.ndarray


def density_change(
    rest: np.ndarray, deformed: np.ndarray, triangles: np.ndarray, root_triangles: np.ndarray
) -> DensityChange:
    """Table 3's density change of the hair roots between the rest and the deformed scalp.

    A triangle holding ``c >= 1`` roots has density ``c / A`` at rest and ``c / A'`` after
    the relocation (roots keep their triangle), a relative change of ``A / A' - 1``
    (positive where the scalp was compressed). Triangles without roots (0/0) are left out.

    Parameters
    ----------
    rest : (n, 3) float64
        Rest scalp vertices (m).
    deformed : (n, 3) float64
        Deformed scalp vertices (m).
    triangles : (m, 3) int64
        Scalp triangles.
    root_triangles : (R,) int64
        The scalp triangle holding each root; ``-1`` for a root outside the scalp (ignored).

    Returns
    -------
    density : DensityChange
        ``linf`` and ``l1`` are ``inf`` when a triangle holding roots collapsed to zero area.

    Raises
    ------
    InputError
        Bad shapes or ids, non-finite positions, or a triangle holding roots with zero
        rest area.
    """
    source = "density_change"
    rest = check_points(rest, 3, "rest", source)
    deformed = check_points(deformed, 3, "deformed", source)
    if deformed.shape != rest.shape:
        raise refuse(f"deformed {deformed.shape} and rest {rest.shape} differ in shape", source)
    triangles = check_triangles(triangles, len(rest), source)
    root_triangles = index_array(root_triangles, 1, "root_triangles", source)
    if root_triangles.size and (root_triangles.min() < -1 or root_triangles.max() >= len(triangles)):
        raise refuse(f"root_triangles must lie in -1 .. {len(triangles) - 1}", source)

    held = np.flatnonzero(np.bincount(root_triangles[root_triangles >= 0], minlength=len(triangles)))
    if held.size == 0:
        return DensityChange(0.0, 0.0, np.zeros(0), np.zeros(0, dtype=np.int64))
    before = triangle_areas(rest, triangles[held])
    if (before <= 0).any():
        raise refuse(f"{int((before <= 0).sum())} scalp triangles holding roots have zero rest area", source)
    after = triangle_areas(deformed, triangles[held])
    with np.errstate(divide="ignore"):
        changes = before / after - 1.0
    magnitude = np.abs(changes)
    return DensityChange(float(magnitude.mean()), float(magnitude.max()), changes, held)
