"""What a fine-level chunk needs besides the artifact and the target (solver/adaptation/fine/fine_chunks.py):
its inputs round-trip through a file, and inputs that do not fit the hairstyle are refused by name. The chunks
themselves, solved elsewhere bit for bit, are tested with solver/distributed.py."""

import numpy as np
import pytest

from hairport.solver.adaptation.fine.fine_chunks import FineInputs
from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import Hair

#: three strands of 4, 3 and 5 particles; strands 0 and 2 are the guides
COUNTS = np.array([4, 3, 5])
GUIDES = np.array([0, 2])


@pytest.fixture
def hair():
    rng = np.random.default_rng(0)
    return Hair(rng.normal(size=(int(COUNTS.sum()), 3)), np.concatenate([[0], np.cumsum(COUNTS)]))


def test_inputs_round_trip_with_and_without_the_hairline_arrays(hair, tmp_path):
    rng = np.random.default_rng(1)
    plain = FineInputs(rng.normal(size=(9, 3)), rng.normal(size=(12, 3)))
    edited = FineInputs(plain.guide_points, plain.initial, gamma=rng.uniform(size=12), start=rng.normal(size=(12, 3)))
    for inputs in (plain, edited):
        inputs.save(tmp_path / "inputs.npz")
        back = FineInputs.load(tmp_path / "inputs.npz", hair, GUIDES)
        for name in ("guide_points", "initial", "gamma", "start"):
            expected, found = getattr(inputs, name), getattr(back, name)
            assert (expected is None and found is None) or np.array_equal(expected, found), name


def test_inputs_of_another_groom_are_refused_by_name(hair, tmp_path):
    FineInputs(np.zeros((3, 3)), np.zeros((12, 3))).save(tmp_path / "inputs.npz")
    with pytest.raises(InputError) as error:
        FineInputs.load(tmp_path / "inputs.npz", hair, GUIDES)
    assert error.value.code == "bad_fine_inputs" and "guide_points" in str(error.value)
