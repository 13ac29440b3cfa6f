"""Fixtures of the hair file tests."""

import pytest

from hairport.solver.model.hair import Hair
from tests.solver.io.hair.samples import helix_hair


@pytest.fixture
def groom() -> Hair:
    """40 helical strands with per-point thickness and color."""
    return helix_hair(40, thickness=True, color=True)
