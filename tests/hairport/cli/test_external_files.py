"""The command line reads the user's own files whole: a USD stage composes the layers it names beside it, a
.gltf reads its buffer file, where the readers' default (uploads: the service, the worker) refuses both."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from hairport import cli
from hairport.solver.io.character.load import read_character
from hairport.solver.io.hair import read_hair, write_hair
from hairport.solver.model.errors import InputError
from tests.hairport.cli.helpers import BASELINE, N_STRANDS
from tests.solver.io.hair.samples import helix_hair


def composed_groom(folder, hair, units: str = "m") -> None:
    """``groom.usda``: a stage of nothing but a relative sublayer, ``layers/strands.usda``, holding ``hair``."""
    (folder / "layers").mkdir()
    write_hair(folder / "layers" / "strands.usda", hair, units=units)
    meters = {"m": 1, "mm": 0.001}[units]
    (folder / "groom.usda").write_text(f"#usda 1.0\n(\n    metersPerUnit = {meters}\n"
                                       "    subLayers = [@./layers/strands.usda@]\n)\n")


def test_convert_composes_a_local_stage(tmp_path, capsys):
    hair = helix_hair(7)
    composed_groom(tmp_path, hair, units="mm")
    assert cli.main(["convert", str(tmp_path / "groom.usda"), str(tmp_path / "out.npz")]) == 0
    assert "7 strands" in capsys.readouterr().out
    back = read_hair(tmp_path / "out.npz", units="mm")
    np.testing.assert_array_equal(back.offsets, hair.offsets)
    np.testing.assert_allclose(back.points, hair.points, atol=1e-8)
    with pytest.raises(InputError) as caught:  # the same stage, read as an upload is
        read_hair(tmp_path / "groom.usda", units="mm")
    assert caught.value.code == "external_reference"


def test_retarget_reads_a_gltf_with_its_buffer_file_and_a_composed_groom(world, tmp_path, capsys):
    d = world["dir"]
    mesh = trimesh.Trimesh(world["source"].vertices, world["source"].faces, process=False)
    files = trimesh.exchange.gltf.export_gltf(mesh, embed_buffers=False)
    document = json.loads(files["model.gltf"])
    assert all(buffer["uri"].startswith("gltf_buffer_") for buffer in document["buffers"])
    for name, data in files.items():
        (tmp_path / ("source.gltf" if name == "model.gltf" else name)).write_bytes(data)
    (tmp_path / "source.skeleton.json").write_bytes((d / "source.skeleton.json").read_bytes())
    composed_groom(tmp_path, world["hair"])
    out = tmp_path / "out"
    out.mkdir()
    code = cli.main(["retarget", "--source", str(tmp_path / "source.gltf"), "--target", str(d / "target.obj"),
                     "--hair", str(tmp_path / "groom.usda"), "--out", str(out / "result.npz"), "--method", BASELINE,
                     "--quiet"])
    assert code == 0, capsys.readouterr().err
    assert read_hair(out / "result.npz").n_strands == N_STRANDS
    for call in (lambda: read_character(tmp_path / "source.gltf"), lambda: read_hair(tmp_path / "groom.usda")):
        with pytest.raises(InputError) as caught:
            call()
        assert caught.value.code == "external_reference"
