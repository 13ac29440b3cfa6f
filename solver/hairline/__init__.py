"""Hairline edits (paper Sec. 6): the requested edit (edit, curve, presets), the scalp and its head
patch (scalp, head_patch), the head chart (head_chart, Eq. 18-19), the embedded membrane
(membrane, Eq. 15-17) and its projected-Newton solve (newton, kinks), the root relocation
(relocation), its Sec. 7.5 baselines (baselines, checks), Table 3's density change (density)
and the adaptive weights of the re-solve (weights, Eq. 20)."""
