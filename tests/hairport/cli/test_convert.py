"""``hairport convert`` (hairport/cli/convert.py): formats and units by extension and flag, exit codes, no partial output."""

import numpy as np

from hairport.cli import main
from hairport.solver.io.hair import read_hair, recorded_units, write_hair
from tests.solver.io.hair.samples import helix_hair


def test_convert_through_usd_ply_npz_and_hair_keeps_points_and_units(tmp_path, capsys):
    hair = helix_hair(n_strands=6, thickness=True, color=True)
    write_hair(tmp_path / "in.npz", hair, units="mm")
    assert main(["convert", str(tmp_path / "in.npz"), str(tmp_path / "a.usda")]) == 0  # the archive's mm kept
    assert recorded_units(tmp_path / "a.usda") == "mm"
    assert main(["convert", str(tmp_path / "a.usda"), str(tmp_path / "b.ply"), "--out-units", "cm"]) == 0
    assert main(["convert", str(tmp_path / "b.ply"), str(tmp_path / "c.usdc"), "--units", "cm"]) == 0
    assert main(["convert", str(tmp_path / "c.usdc"), str(tmp_path / "d.hair")]) == 0
    out = capsys.readouterr().out
    assert "6 strands" in out and "(usda, mm -> ply, cm)" in out
    back = read_hair(tmp_path / "d.hair", units="cm")
    np.testing.assert_array_equal(back.offsets, hair.offsets)
    np.testing.assert_allclose(back.points, hair.points, rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(back.thickness, hair.thickness, rtol=1e-5)
    np.testing.assert_allclose(back.color, hair.color, rtol=0, atol=0.5 / 255 + 1e-7)  # PLY's colours are 8-bit


def test_convert_refuses_bad_input_with_code_2_and_writes_nothing(tmp_path, capsys):
    (tmp_path / "bad.usda").write_text("#usda 1.0\ndef BasisCurves \"h\" {\n")
    assert main(["convert", str(tmp_path / "bad.usda"), str(tmp_path / "out.npz")]) == 2
    assert "not a readable USD stage" in capsys.readouterr().err
    write_hair(tmp_path / "ok.npz", helix_hair(n_strands=2))
    assert main(["convert", str(tmp_path / "ok.npz"), str(tmp_path / "out.xyz")]) == 2
    assert "unknown hair file type" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.usda", "ok.npz"]
