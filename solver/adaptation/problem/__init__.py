"""Eq. 1 under Eq. 12-13 over strands: the energies (with the spacing term), the strand problem and its
Newton model, block-tridiagonal algebra, and the constraints."""
