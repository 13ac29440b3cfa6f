"""Tests for solver/wrap/options.py: the wrap's settings."""

from __future__ import annotations

import numpy as np

from hairport.solver.wrap.options import WrapOptions


def test_the_schedule_runs_stiff_to_soft_and_landmark_weights_repeat_their_last():
    options = WrapOptions()
    assert np.all(np.diff(options.stiffness) < 0)
    assert [options.landmark_weight(step) for step in range(6)] == [1.0, 0.5, 0.3, 0.3, 0.3, 0.3]
    assert WrapOptions(landmark_weights=()).landmark_weight(3) == 0.0
    assert 0.0 < options.max_normal_angle_deg < 90.0 and options.max_distance_m > 0.0
