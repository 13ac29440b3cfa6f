"""All-or-nothing output files, and a retarget's result written in the groom's frame."""

import json
import os
import stat

import numpy as np
import pytest

from hairport import solver
from hairport.outputs import OutputSet, add_result, json_default
from hairport.solver import FILE_MODE, atomic_write_bytes, options
from hairport.solver.model.frame import InputFrame
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.toy import toy_character
from tests.solver.frames import hair_in


def test_files_appear_only_on_commit(tmp_path):
    with OutputSet() as outputs:
        outputs.add(tmp_path / "a" / "hair.data", lambda path: path.write_bytes(b"1234"))
        outputs.add_json(tmp_path / "report.json", {"n": np.int64(3), "v": np.array([1.5, 2.0])})
        assert sorted(p.name for p in tmp_path.rglob("*") if p.is_file() and not p.name.startswith(".")) == []
        written = outputs.commit()
    assert [p.name for p in written] == ["hair.data", "report.json"]
    assert (tmp_path / "a" / "hair.data").read_bytes() == b"1234"
    assert json.loads((tmp_path / "report.json").read_text()) == {"n": 3, "v": [1.5, 2.0]}
    assert [p.name for p in tmp_path.rglob(".*")] == []


def test_a_failure_leaves_nothing(tmp_path):
    def broken(path):
        path.write_bytes(b"half")
        raise OSError("disk full")

    with pytest.raises(OSError):
        with OutputSet() as outputs:
            outputs.add(tmp_path / "first.data", lambda path: path.write_bytes(b"ok"))
            outputs.add(tmp_path / "second.data", broken)
    assert list(tmp_path.iterdir()) == []


def test_temporary_names_keep_the_extension(tmp_path):
    seen = []
    with OutputSet() as outputs:
        outputs.add(tmp_path / "x.ply", lambda path: seen.append(path.suffix) or path.write_text(""))
        outputs.abort()
    assert seen == [".ply"] and list(tmp_path.iterdir()) == []


def test_json_default_refuses_other_objects():
    assert json_default(np.float32(0.5)) == 0.5
    with pytest.raises(TypeError, match="not JSON serialisable: object"):
        json_default(object())


@pytest.fixture
def umask():
    """Set the process umask for a test (``umask(value)``), restored afterwards."""
    old = os.umask(0o022)
    try:
        yield os.umask
    finally:
        os.umask(old)


@pytest.mark.parametrize("mask, mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_every_output_has_the_file_mode_less_the_umask(tmp_path, umask, mask, mode):
    umask(mask)
    with OutputSet() as outputs:
        outputs.add(tmp_path / "preview.png", lambda path: path.write_bytes(b"png"))  # writes into the temporary
        outputs.add_json(tmp_path / "report.json", {"n": 1})
        outputs.add(tmp_path / "hair.data", lambda path: atomic_write_bytes(path, b"hair"))  # replaces it
        written = outputs.commit()
    assert FILE_MODE & ~mask == mode
    assert {p.name: stat.S_IMODE(p.stat().st_mode) for p in written} == dict.fromkeys(
        ["preview.png", "report.json", "hair.data"], mode)


@pytest.fixture(scope="module")
def retargeted():
    """A toy groom read in centimetres with Z up, retargeted onto its own body (a baseline: fast)."""
    toy = toy_character()
    frame = InputFrame("cm", "z", "-y")
    adaptable = solver.preprocess(toy, generate_groom(toy, "short", 30, 6, seed=1), solver.PreprocessOptions(guides=5),
                                  frame=frame)
    return adaptable, solver.retarget(adaptable, toy, solver.RetargetOptions(method="root-translate")), toy


def test_a_result_is_written_in_the_grooms_units_and_axes_with_its_report_and_preview(tmp_path, retargeted):
    adaptable, result, toy = retargeted
    report = {**result.report(), "pair": "toy"}
    hair = {"npz": tmp_path / "result.npz", "ply": tmp_path / "result.ply"}
    with OutputSet() as outputs:
        add_result(outputs, adaptable, result, toy, hair, report=(tmp_path / "report.json", report),
                   preview=tmp_path / "preview.png", flag_guides=True)
        assert [p for p in tmp_path.iterdir() if not p.name.startswith(".")] == []  # nothing before the commit
        written = outputs.commit()
    assert [p.name for p in written] == ["result.npz", "result.ply", "report.json", "preview.png"]
    expected = hair_in(adaptable.frame, result.hair).points
    np.testing.assert_allclose(expected[:, 2], 100.0 * result.hair.points[:, 1], rtol=1e-15)  # centimetres, Z up
    for path in hair.values():
        back = solver.read_hair(path, units="cm")  # read back in meters, in the file's axes (PLY: float32)
        np.testing.assert_allclose(back.points, expected / 100.0, rtol=0, atol=1e-6)
        flags = back.attributes_of("strand")[options.GUIDE_FLAG].values
        assert np.flatnonzero(flags).tolist() == sorted(adaptable.multiscale.guides.tolist())
    assert solver.recorded_hair_units(hair["npz"]) == "cm"
    with np.load(hair["npz"]) as archive:
        np.testing.assert_allclose(archive["points"], expected, rtol=1e-15, atol=0)
    document = json.loads((tmp_path / "report.json").read_text())
    assert document["pair"] == "toy" and document["metrics"]["method"] == "root-translate"
    assert (tmp_path / "preview.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_result_without_flags_report_or_preview_is_the_hair_alone(tmp_path, retargeted):
    adaptable, result, toy = retargeted
    with OutputSet() as outputs:
        add_result(outputs, adaptable, result, toy, {"npz": tmp_path / "result.npz"})
        written = outputs.commit()
    assert [p.name for p in written] == ["result.npz"]
    assert options.GUIDE_FLAG not in solver.read_hair(written[0], units="cm").attributes_of("strand")
