"""Hairline edits (paper Sec. 6): curves, presets, scalp, head chart, membrane (Eq. 15-19), relocation, weights (Eq. 20-21)."""
