"""The initial transfer (paper Sec. 4.2-4.3): bone anchoring (Eq. 2-3), smoothing (Eq. 4-6)."""
