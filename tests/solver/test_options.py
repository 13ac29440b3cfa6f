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
