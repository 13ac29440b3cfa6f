"""The memory estimate: bytes per particle, the k term, and the refusal's code."""

import pytest

from hairport.solver import InputError
from hairport.solver.budget import BYTES_PER_NEIGHBOUR, BYTES_PER_PARTICLE, MEASURED_K, check_memory, estimate_bytes


def test_the_estimate_grows_with_particles_and_neighbours():
    assert estimate_bytes(10**6) == 1_100 * 10**6 == BYTES_PER_PARTICLE * 10**6
    assert estimate_bytes(10**6, k=MEASURED_K + 10) - estimate_bytes(10**6) == 10 * BYTES_PER_NEIGHBOUR * 10**6
    assert estimate_bytes(10**6, k=1) == estimate_bytes(10**6)


def test_over_the_budget_is_refused_with_its_code():
    check_memory(7_000_000, 8 * 1024**3)
    check_memory(10**9, None)
    with pytest.raises(InputError) as error:
        check_memory(8_000_000, 8 * 1024**3, source="groom.npz")
    assert error.value.code == "over_memory_budget"
    assert "8,000,000 particles need about 8.2 GiB" in error.value.problem
