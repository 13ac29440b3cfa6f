"""The fine level (Eq. 14): independent strands on compiled per-strand kernels (the active-set loop's
compiled level, its QP, line search and band kernels) and the chunks any process can rebuild."""
