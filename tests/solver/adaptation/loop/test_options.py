"""What both QP backends share (solver/adaptation/loop/options.py): the damping rule, the solve report, the options."""

from dataclasses import asdict

import numpy as np

from hairport.solver.adaptation.loop.options import (
    DAMPING_FACTOR,
    MAX_RADIAL_DAMPING,
    MIN_RADIAL_DAMPING,
    Cancelled,
    SolveOptions,
    SolveReport,
    adapt_damping,
)


def test_damping_rises_after_a_poor_step_and_falls_after_a_good_one():
    damping = np.array([0.01, 0.01, 0.01, 0.01, 0.01, 0.01, 0.01])
    actual = np.array([-0.1, -0.9, -0.5, -0.25, -0.75, 1.0, -1.0])
    predicted = np.array([-1.0, -1.0, -1.0, -1.0, -1.0, -1.0, 0.0])
    # ratios 0.1 (poor), 0.9 (good), 0.5, 0.25 and 0.75 (the bounds keep it), -1 (the merit rose),
    # and no predicted decrease (ratio 0)
    np.testing.assert_array_equal(adapt_damping(damping, actual, predicted), [0.04, 0.0025, 0.01, 0.01, 0.01, 0.04, 0.04])


def test_damping_stays_within_its_bounds():
    damping = np.array([MAX_RADIAL_DAMPING, MIN_RADIAL_DAMPING, 0.5, 2e-4])
    actual = np.array([0.0, -1.0, 0.0, -1.0])
    predicted = np.full(4, -1.0)
    np.testing.assert_array_equal(adapt_damping(damping, actual, predicted), [1.0, 1e-4, 1.0, 1e-4])
    assert DAMPING_FACTOR == 4.0  # 0.5 * 4 hits the cap, 2e-4 / 4 the floor


def test_damping_of_one_scalar_step():
    assert float(adapt_damping(0.01, -0.9, -1.0)) == 0.0025
    assert float(adapt_damping(0.01, -0.1, -1.0)) == 0.04
    assert float(adapt_damping(0.01, -0.1, 1e-3)) == 0.04  # the model predicted a rise


def test_solve_report_fields_are_the_job_reports_keys():
    report = asdict(SolveReport(backend="active-set"))
    assert list(report) == [
        "backend", "iterations", "converged", "max_step", "min_clearance", "step_fractions", "pushed_out", "seconds",
        "groups", "converged_groups", "stopped", "capped", "segments_crossing", "segment_rounds", "segments_left", "segment_seconds",
        "open_groups",
        "active_set_rounds", "cg_steps", "merit",
        "osqp_status", "osqp_iterations",
    ]
    assert report["backend"] == "active-set" and report["iterations"] == 0 and report["converged"] is False
    assert SolveReport().max_step is not SolveReport().max_step  # lists are per report


def test_solve_options_defaults_and_cancellation():
    options = SolveOptions()
    assert (options.eps_c, options.max_iterations, options.step_tolerance) == (5e-4, 30, 1e-5)  # Table 1, meters
    assert options.energy_tolerance == 0.0
    assert issubclass(Cancelled, RuntimeError)  # callers that catch RuntimeError also see a cancelled solve
