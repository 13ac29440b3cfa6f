"""Fixtures shared by the tests of this folder."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from hairport.solver.io.hair import write_hair
from hairport.solver.synthetic import toy
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import write_character
from tests.hairport.cli.helpers import N_PARTICLES, N_STRANDS


@pytest.fixture(scope="module")
def world(tmp_path_factory) -> dict:
    """Source / target characters, variants of them, and a groom, as files."""
    d = tmp_path_factory.mktemp("cli-inputs")
    source = toy.toy_character(name="source")
    target = toy.toy_character(head_scale=(1.1, 0.95, 1.05), neck_length=0.15, shoulder_width=0.42, name="target")
    write_character(source, d / "source.obj", d / "source.skeleton.json")
    write_character(target, d / "target.obj", d / "target.skeleton.json")
    # the target mesh alone: its skeleton must be transferred from the source
    shutil.copy(d / "target.obj", d / "bare.obj")

    hair = generate_groom(source, "short", N_STRANDS, N_PARTICLES, seed=0)
    assert (hair.n_strands, hair.n_particles) == (N_STRANDS, N_STRANDS * N_PARTICLES)
    write_hair(d / "hair.data", hair)
    write_hair(d / "hair.hair", hair)
    # float64 archives: .data rounds to float32 differently in m and cm (~8e-8 m), and the
    # push-out of the baseline amplifies that to ~2e-5 m on a few particles
    write_hair(d / "hair.npz", hair)
    write_hair(d / "hair_cm.npz", hair, units="cm")
    return {"dir": d, "source": source, "target": target, "hair": hair}


@pytest.fixture
def out(tmp_path) -> Path:
    """An empty output folder; failed runs must leave it empty."""
    path = tmp_path / "out"
    path.mkdir()
    return path
