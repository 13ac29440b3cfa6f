"""Fixtures shared by the tests of this folder."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
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


@pytest.fixture(scope="session")
def remeshed_world(tmp_path_factory) -> dict:
    """A groom of the average MakeHuman female (40 strands, preprocessed twice: 20 and 10 guides) and targets of
    another topology: the heavy male remeshed to 5,000 vertices (OBJ, no units, no rig), his head cut at the neck
    written in millimetres with Z up and the face toward -Y, and a sphere of a head's size."""
    import trimesh

    from hairport import cli
    from hairport.solver.io.character.obj import write_obj
    from hairport.solver.model.frame import InputFrame
    from hairport.solver.synthetic.makehuman import PRESETS, build_character
    from hairport.solver.synthetic.remesh import head_cut, neck_height, remeshed_character

    d = tmp_path_factory.mktemp("cli-remeshed")
    source, male = build_character(PRESETS["average-female"]), build_character(PRESETS["heavy-male"])
    write_character(source, d / "female.obj", d / "female.skeleton.json")
    write_hair(d / "short.data", generate_groom(source, "short", 40, 6, seed=2))
    for guides in (20, 10):
        assert cli.main(["preprocess", "--source", str(d / "female.obj"), "--hair", str(d / "short.data"),
                         "--guides", str(guides), "--out", str(d / f"short{guides}.hpa"), "--quiet"]) == 0
    body = remeshed_character(male, 5000, seed=2)
    write_obj(d / "male.obj", body.vertices, body.faces, "the heavy male remeshed")
    head, _ = head_cut(body, neck_height(male))
    frame = InputFrame("mm", "+z", "-y")  # the file's axes: canonical +Y is its +Z, canonical +Z its -Y
    in_file = np.stack([head.vertices[:, 0], -head.vertices[:, 2], head.vertices[:, 1]], axis=1) * 1e3
    np.testing.assert_allclose(in_file, frame.axes_out(head.vertices) / frame.scale, atol=1e-9)
    write_obj(d / "head.obj", in_file, head.faces, "the heavy male's head in mm, Z up")
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=0.11)
    write_obj(d / "sphere.obj", np.asarray(sphere.vertices) + [0.0, 0.75, 0.0], np.asarray(sphere.faces), "a ball")
    return {"dir": d, "adaptable": d / "short20.hpa", "male": body, "head": head, "head_frame": frame}
