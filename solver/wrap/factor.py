"""Sparse factorisation of the wrap's normal equations, kept while the matrix holds.

SuperLU (``scipy.sparse.linalg.splu``) with the minimum-degree ordering of ``A + A^T`` in its
symmetric mode (diagonal pivots first), measured against the alternatives on the fitting
matrix (``bench/wrap.py --factor`` and the wrap's own runs, 2 shared cores):

=================================  ===========  ===========  ===========
seconds per factorisation          MH head      MH body      toy body
=================================  ===========  ===========  ===========
unknowns                           15,724       53,520       15,368
splu, MMD on A + A^T, symmetric    0.13         0.50         0.11
splu, COLAMD                       0.19         0.47         0.31
qdldl (AMD; pip, Apache-2.0)       0.10         0.37         1.03
qdldl ``update`` (same pattern)    0.07         0.32         --
CHOLMOD (cholespy wheel)           0.15         0.64         0.22
conjugate gradients, Jacobi        4.3          17           --
=================================  ===========  ===========  ===========

(MH: the MakeHuman body and its head; toy: :func:`hairport.solver.synthetic.toy.toy_character`,
rings of 48 vertices closed by two poles.) qdldl reuses its symbolic analysis and is 1.3-1.9x
faster on the MakeHuman meshes, but nine times slower on the toy's ring mesh (1.0 s: its
factors hold more entries than SuperLU's L, and it factors column by column), and its solves (one column at a time) cost more than the refactorisations they
save: a whole wrap took the same 3 s with either on a 20k head. SuperLU is fast on both kinds
of mesh, solves the three columns at once (~0.01 s) and needs no new dependency; scikit-sparse
(CHOLMOD) has no wheels. The wrap factors about once per stiffness step (:mod:`.nricp`: 7-14
times per wrap in ``bench/wrap.py``), so a reusable symbolic analysis would save little.
SuperLU must be told that the matrix needs no pivoting (:data:`DIAGONAL_PIVOT_THRESHOLD`).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

#: SuperLU's column ordering: minimum degree on the structure of A + A^T (A is symmetric)
ORDERING = "MMD_AT_PLUS_A"
#: SuperLU takes the diagonal as pivot when it is at least this share of its column's largest
#: entry. A is symmetric positive definite, so elimination needs no pivoting: 0 takes the
#: diagonal always and keeps the ordering's fill. With SuperLU's default threshold soft steps
#: lose it: on a 5k-vertex hair region at stiffness 0.2
#: the factors grew from 3.4 M to 19 M entries (4 s), at 0.1 to 103 M (260 s); with 0 they stay
#: at 3.4 M down to 0.001, residuals 1e-13 to 1e-9 relative
DIAGONAL_PIVOT_THRESHOLD = 0.0


class SymmetricFactor:
    """A factorisation of symmetric positive definite matrices, refactored when asked."""

    def __init__(self):
        self._lu = None
        self.factorisations = 0

    def factor(self, matrix: sp.csc_matrix) -> None:
        """Factor ``matrix (N, N)`` (CSC, both triangles stored)."""
        self._lu = spla.splu(matrix, permc_spec=ORDERING, diag_pivot_thresh=DIAGONAL_PIVOT_THRESHOLD,
                             options={"SymmetricMode": True})
        self.factorisations += 1

    def solve(self, rhs: np.ndarray) -> np.ndarray:
        """``A^-1 rhs`` for ``rhs (N, k)`` float64."""
        if self._lu is None:
            raise RuntimeError("solve before factor")
        return self._lu.solve(np.asarray(rhs, dtype=np.float64))
