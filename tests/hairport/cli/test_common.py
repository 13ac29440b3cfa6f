"""What the commands share: progress lines, units of meshes, and the source arguments."""

import argparse

import pytest

from hairport.cli.common import StageProgress, check_source_arguments, mesh_units
from hairport.solver import InputError


def test_progress_lines(capsys):
    StageProgress()("solve", 0.5, "iteration 3")
    StageProgress(quiet=True)("solve", 0.5, "not printed")
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "solve" in err and " 50.0%  iteration 3" in err and err.startswith("[")


def test_units_apply_to_meshes_without_a_sidecar(tmp_path):
    args = argparse.Namespace(units="cm")
    (tmp_path / "with.obj").write_text("")
    (tmp_path / "with.skeleton.json").write_text("{}")
    (tmp_path / "bare.obj").write_text("")
    assert mesh_units(args, str(tmp_path / "bare.obj"), None) == "cm"
    assert mesh_units(args, str(tmp_path / "with.obj"), None) is None
    assert mesh_units(args, str(tmp_path / "bare.obj"), str(tmp_path / "given.json")) is None


@pytest.mark.parametrize("given, words", [
    (dict(adaptable="a.hpa", source="s.obj"), "not both"),
    (dict(adaptable="a.hpa", guides=10), "not both"),
    (dict(source="s.obj"), "give --adaptable, or --source with --hair"),
    (dict(), "give --adaptable, or --source with --hair"),
])
def test_source_arguments(given, words):
    args = argparse.Namespace(**{"adaptable": None, "source": None, "hair": None, "source_skeleton": None,
                                 "guides": None, **given})
    with pytest.raises(InputError, match=words) as refused:
        check_source_arguments(args)
    assert refused.value.code == "bad_option"
