"""Shape adaptation (paper Sec. 4.4-5): Eq. 1 under Eq. 12-13, by level.

``problem/`` (energies Eq. 7-11, constraints Eq. 12-13) and ``source/`` (guides, kNN sets) below
``loop/`` (the one active-set outer loop and its options), below the two levels that run it,
``coupled/`` and ``fine/``; above them ``solve.py`` picks a level or QP backend and
``multiscale.py`` (Eq. 14) runs both levels.
"""
