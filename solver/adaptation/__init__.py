"""Shape adaptation (paper Sec. 4.4-5): energies Eq. 7-11, constraints Eq. 12-13, QP backends, multi-scale Eq. 14."""
