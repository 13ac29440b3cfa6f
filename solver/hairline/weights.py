"""Eq. 20: adaptive weights that relax Eq. 10-11 near relocated roots (0 at the root, rising to 1 along the strand)."""

from __future__ import annotations

import numpy as np

from hairport.solver.model.hair import Hair

#: sigma of Eq. 20 (unitless; Table 1)
GAMMA_SIGMA = 0.2


def adaptive_weights(hair: Hair, root_travel: np.ndarray, sigma: float = GAMMA_SIGMA) -> np.ndarray:
    """Eq. 20: ``gamma_i = 1 - exp(-sigma (s_i / r_i)^2)``.

    ``s_i`` is the arc length (m) from particle ``i`` to its root along the source strand and
    ``r_i`` how far (m) that strand's root moved in the relocation. ``gamma`` is 0 at a
    root that moved and tends to 1 along the strand: it relaxes the inter-strand and
    hair-body terms near relocated roots (DESIGN.md on Eq. 20). Strands whose root did not
    move (``r = 0``) keep weight 1 everywhere, roots included.

    Parameters
    ----------
    hair : Hair
        The source hairstyle (arc lengths are measured on it).
    root_travel : (S,) float64
        Distance each strand's root moved (m), >= 0.
    sigma : float

    Returns
    -------
    gamma : (N,) float64
    """
    root_travel = np.asarray(root_travel, dtype=np.float64)
    if root_travel.shape != (hair.n_strands,):
        raise ValueError(f"root_travel has shape {root_travel.shape}, expected ({hair.n_strands},)")
    segment = np.linalg.norm(np.diff(hair.points, axis=0), axis=1)
    steps = np.concatenate([[0.0], segment])
    steps[hair.roots] = 0.0  # no length across strand boundaries
    cumulative = np.cumsum(steps)
    arc = cumulative - np.repeat(cumulative[hair.roots], hair.counts)
    travel = np.repeat(root_travel, hair.counts)
    moved = travel > 0
    gamma = np.ones(hair.n_particles)
    ratio = np.divide(arc, travel, out=np.zeros_like(arc), where=moved)
    gamma[moved] = 1.0 - np.exp(-sigma * ratio[moved] ** 2)
    return gamma
