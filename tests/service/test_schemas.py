"""The API's choices and defaults are the solver's and the records' own."""

from typing import get_args

from hairport import solver
from hairport.records import JOB_STATES, BlobRef, CharacterRecord
from hairport.service import schemas
from hairport.solver import options


def test_choices_come_from_their_definitions():
    assert get_args(schemas.HairFormat) == solver.HAIR_FORMATS
    assert get_args(schemas.Units) == solver.UNITS
    assert get_args(schemas.HairlinePresetName) == options.HAIRLINE_PRESETS
    assert get_args(schemas.JobState) == JOB_STATES
    assert get_args(schemas.RetargetOptionsIn.model_fields["qp_backend"].annotation) == options.QP_BACKENDS
    assert get_args(schemas.RetargetOptionsIn.model_fields["wrap"].annotation) == options.WRAP_MODES


def test_defaults_are_the_solver_defaults():
    options = schemas.RetargetOptionsIn()
    defaults = solver.RetargetOptions()
    for name in ("method", "alpha", "beta", "eps_c", "eps_s", "max_iterations", "step_tolerance", "qp_backend",
                 "wrap"):
        assert getattr(options, name) == getattr(defaults, name), name
    hairline = schemas.HairlineIn(preset="round")
    assert (hairline.amount, hairline.method, hairline.parameterization) == (1.0, "membrane", "harmonic")


def test_character_out_flattens_the_record():
    record = CharacterRecord(id="c" * 32, owner="k", created_at=5.0, mesh=BlobRef(sha256="a" * 64, suffix=".obj"),
                             units=None, vertices=4, faces=2, bones=[])
    out = schemas.CharacterOut.of(record)
    # no units given or stated by its files: inferred when the character is used (issue 11; was "m")
    assert (out.units, out.has_skeleton, out.sha256, out.skeleton_sha256) == ("auto", False, "a" * 64, None)
    assert (out.up_axis, out.front_axis) == ("auto", "auto")
