"""The public face of the solver: every exported name resolves, and importing a part stays light."""

import subprocess
import sys

import pytest

import hairport.solver as solver


def test_every_exported_name_resolves():
    assert solver.__all__ == sorted(solver.__all__) and dir(solver) == solver.__all__
    for name in solver.__all__:
        assert getattr(solver, name) is not None, name
    assert solver.HAIR_FORMATS == ("data", "hair", "ply", "npz", "obj", "usd", "usda", "usdc", "abc") and solver.UNITS == ("m", "dm", "cm", "mm")
    with pytest.raises(AttributeError, match="no attribute 'pipeline_internals'"):
        solver.pipeline_internals  # noqa: B018


def test_importing_the_data_model_does_not_load_the_numerical_stack():
    code = ("import sys; import hairport.solver.model.errors; from hairport.solver import InputError;"
            "print(sorted(m for m in ('scipy', 'trimesh', 'igl', 'osqp') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]"
