"""The options of the two stages: defaults (Table 1, meters) and refusals with their codes."""

import math

import pytest

from hairport.solver.hairline.edit import HairlineEdit
from hairport.solver.model.errors import InputError
from hairport.solver.options import METHODS, SOLVER_METHODS, PreprocessOptions, RetargetOptions


def test_table_1_defaults():
    options = RetargetOptions()
    assert (options.method, options.alpha, options.beta, options.eps_c, options.eps_s) == (
        "multiscale", 3e3, 1e3, 5e-4, 0.3)
    assert (PreprocessOptions().k, PreprocessOptions().sigma, PreprocessOptions().guides) == (5, 100.0, 300)
    assert METHODS[:2] == SOLVER_METHODS == ("multiscale", "global") and "rbf-warp" in METHODS


@pytest.mark.parametrize("change, code", [
    ({"method": "magic"}, "unknown_method"),
    ({"method": "global+pushout"}, "unknown_method"),
    ({"alpha": -1.0}, "bad_option"),
    ({"eps_c": math.nan}, "bad_option"),
    ({"energy_tolerance": math.inf}, "bad_option"),
    ({"max_iterations": 0}, "bad_option"),
    ({"qp_backend": "cplex"}, "bad_option"),
    ({"workers": 0}, "bad_option"),
    ({"chunk_particles": 0}, "bad_option"),
    ({"method": "root-translate", "hairline": HairlineEdit(preset="round")}, "bad_option"),
])
def test_retarget_refusals(change, code):
    with pytest.raises(InputError) as refused:
        RetargetOptions(**change).validate()
    assert refused.value.code == code


def test_unknown_method_lists_the_valid_ones():
    with pytest.raises(InputError) as refused:
        RetargetOptions(method="warp").validate()
    assert all(name in str(refused.value) for name in METHODS) and "+pushout" in str(refused.value)
    RetargetOptions(method="rbf-warp+pushout").validate()


@pytest.mark.parametrize("change", [{"k": 0}, {"guides": 0}, {"sigma": -1.0}, {"sigma": math.nan}, {"anchoring": "ribs"}])
def test_preprocess_refusals(change):
    with pytest.raises(InputError) as refused:
        PreprocessOptions(**change).validate()
    assert refused.value.code == "bad_option"


@pytest.mark.parametrize("options", [
    {"k": 10**9}, {"guides": 10**9}, {"k": 0}, {"sigma": float("nan")}, {"guides": 2.5},
])
def test_preprocess_options_out_of_range_are_refused(options):
    from hairport.solver import InputError, PreprocessOptions

    name = next(iter(options))
    with pytest.raises(InputError, match=f"option {name} must be") as error:
        PreprocessOptions(**options).validate()
    assert error.value.code == "bad_option"


@pytest.mark.parametrize("options", [
    {"eps_c": 1e308}, {"alpha": -1.0}, {"alpha": float("nan")}, {"beta": float("inf")},
    {"max_iterations": 10**9}, {"workers": 0}, {"step_tolerance": -1e-9}, {"alpha": "3"},
])
def test_retarget_options_out_of_range_are_refused(options):
    from hairport.solver import InputError, RetargetOptions
    from hairport.solver.options import OPTION_RANGES

    name = next(iter(options))
    with pytest.raises(InputError) as error:
        RetargetOptions(**options).validate()
    assert error.value.code == "bad_option"
    assert name in error.value.problem
    if not isinstance(options[name], str):
        assert f"[{OPTION_RANGES[name].minimum:g}, {OPTION_RANGES[name].maximum:g}]" in error.value.problem


def test_every_default_is_in_its_range():
    from hairport.solver import PreprocessOptions, RetargetOptions

    PreprocessOptions().validate()
    RetargetOptions().validate()
    RetargetOptions(workers=1).validate()


def test_the_documented_table_is_the_one_generated_from_the_ranges():
    from pathlib import Path

    from hairport.solver.options import option_table

    operations = (Path(__file__).parents[2] / "docs" / "operations.md").read_text()
    assert option_table() in operations
