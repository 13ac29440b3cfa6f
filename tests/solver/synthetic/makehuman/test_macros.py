"""Tests for solver/synthetic/makehuman/macros.py: the parameters and the macro target weights."""

from __future__ import annotations

import pytest

from hairport.solver.model.errors import InputError
from hairport.solver.synthetic.makehuman.macros import (
    MakeHumanParams,
    age_from_years,
    macro_target_weights,
    macro_variable_weights,
    years_from_age,
)


def test_params_validation():
    with pytest.raises(InputError, match="gender"):
        MakeHumanParams(gender=1.5)
    with pytest.raises(InputError, match="sum to 1"):
        MakeHumanParams(african=0.5, asian=0.5, caucasian=0.5)
    with pytest.raises(InputError, match="macro"):
        MakeHumanParams(targets={"macrodetails/universal-female-young-averagemuscle-maxweight": 1.0})
    with pytest.raises(InputError, match=r"\[0, 1\]"):
        MakeHumanParams(targets={"head/head-round": 2.0})
    params = MakeHumanParams(targets={"neck/neck-scale-horiz-incr": 0.3, "head/head-round": 0.5})
    assert params.targets == (("head/head-round", 0.5), ("neck/neck-scale-horiz-incr", 0.3))
    assert hash(params) == hash(MakeHumanParams(targets={"head/head-round": 0.5, "neck/neck-scale-horiz-incr": 0.3}))


def test_age_axis():
    assert age_from_years(1) == 0.0
    assert age_from_years(11) == pytest.approx(0.1875)
    assert age_from_years(25) == pytest.approx(0.5)
    assert age_from_years(90) == 1.0
    assert years_from_age(age_from_years(40.0)) == pytest.approx(40.0)


@pytest.mark.parametrize("value", [0.0, 0.1, 0.1875, 0.3, 0.5, 0.77, 1.0])
def test_macro_weights_partition_of_unity(value):
    params = MakeHumanParams(gender=value, age=value, muscle=value, weight=value, height=value, proportions=value,
                             african=0.2, asian=0.3, caucasian=0.5)
    variables = macro_variable_weights(params)
    for name in ("gender", "age", "muscle", "weight", "race"):
        assert sum(variables[name].values()) == pytest.approx(1.0)
        assert min(variables[name].values()) >= 0.0
    assert sum(variables["height"].values()) == pytest.approx(abs(2 * value - 1))
    weights = macro_target_weights(params)
    race = sum(w for k, w in weights.items() if k.count("/") == 1 and not k.startswith("macrodetails/universal"))
    universal = sum(w for k, w in weights.items() if k.startswith("macrodetails/universal"))
    height = sum(w for k, w in weights.items() if k.startswith("macrodetails/height/"))
    assert race == pytest.approx(1.0)
    assert universal == pytest.approx(1.0)
    assert height == pytest.approx(abs(2 * value - 1))
    assert not any("-baby-" in k for k in weights if k.startswith("macrodetails/proportions/"))


def test_age_weights_follow_makehuman():
    weights = macro_variable_weights(MakeHumanParams(age=0.1))["age"]
    assert weights["baby"] == pytest.approx(1 - 0.1 / 0.1875)
    assert weights["child"] == pytest.approx(0.1 / 0.1875)
    weights = macro_variable_weights(MakeHumanParams(age=0.75))["age"]
    assert weights == pytest.approx({"baby": 0.0, "child": 0.0, "young": 0.5, "old": 0.5})


def test_blended_parameters_move_every_slider_linearly():
    from hairport.solver.synthetic.makehuman.builder import PRESETS
    from hairport.solver.synthetic.makehuman.macros import blend_params

    first, last = PRESETS["average-female"], PRESETS["heavy-male"]
    assert blend_params(first, last, 0.0) == first and blend_params(first, last, 1.0) == last
    middle = blend_params(first, last, 0.25)
    assert middle.weight == pytest.approx(0.75 * first.weight + 0.25 * last.weight)
    assert middle.target_weights["head/head-round"] == pytest.approx(0.25 * 0.5)  # only the heavy male has it
