"""Property: a groom with degenerate parts of any mix of kinds, anywhere in it, either retargets (same layout,
finite points, collapsed strands on their roots, repeated points together, no particle inside) or is refused
by an InputError with a code; no other exception (solver/model/degenerate.py)."""

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hairport.solver.inputs import canonical_source
from hairport.solver.model.degenerate import STRAY_STRANDS
from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import EMPTY_HAIR, Hair
from hairport.solver.options import PreprocessOptions, RetargetOptions
from hairport.solver.pipeline import preprocess, retarget
from hairport.solver.synthetic.groom import generate_groom

#: the codes a degenerate groom may be refused with: a stray strand, nothing but degenerate strands, or a strand
#: whose segments no push clears of the body (a straight one through the head)
REFUSALS = {STRAY_STRANDS, EMPTY_HAIR, "penetration_remaining"}
KINDS = ("collapse", "origin", "origin_tail", "repeat", "tiny_strand", "tiny_segment", "duplicate", "two_points",
         "collinear", "zigzag", "stray")
#: a small groom, few guides and iterations: an example takes about a second
STRANDS, PARTICLES, GUIDES, ITERATIONS = 24, 6, 8, 15


@pytest.fixture(scope="module")
def strands(toy_a):
    hair = generate_groom(toy_a, "short", STRANDS, PARTICLES, seed=1)
    return [hair.strand(s).copy() for s in range(hair.n_strands)]


def edited(strands: list[np.ndarray], edits: list[tuple[str, int, int]]) -> list[np.ndarray]:
    """``strands`` with each ``(kind, strand, parameter)`` edit applied in turn."""
    out = [s.copy() for s in strands]
    for kind, which, parameter in edits:
        i = which % len(out)
        strand = out[i]
        j = parameter % len(strand)
        direction = np.array([0.6, -0.8, 0.0])
        if kind == "collapse":
            out[i] = np.repeat(strand[:1], len(strand), axis=0)
        elif kind == "origin":
            out.insert(i, np.zeros((2 + parameter % 6, 3)))
        elif kind == "origin_tail":  # a damaged file read as zeros from point j on
            strand[max(j, 1):] = 0.0
        elif kind == "repeat":
            out[i] = np.insert(strand, j, strand[j], axis=0)
        elif kind == "tiny_strand":
            out[i] = strand[0] + 1e-12 * np.arange(len(strand))[:, None] * direction
        elif kind == "tiny_segment":
            out[i] = np.insert(strand, j + 1, strand[j] + 1e-12 * direction, axis=0)
        elif kind == "duplicate":
            out.insert(parameter % (len(out) + 1), strand.copy())
        elif kind == "two_points":
            out[i] = strand[:2].copy()
        elif kind == "collinear":  # a straight strand of the same length along its first segment
            step = strand[1] - strand[0]
            out[i] = strand[0] + np.arange(len(strand))[:, None] * step
        elif kind == "zigzag":  # folded back on itself: each segment antiparallel to the one before
            out[i] = strand[0] + (np.arange(len(strand)) % 2)[:, None] * (strand[1] - strand[0])
        elif kind == "stray":  # 1 km to float32's limit away
            out[i] = strand + np.array([0.0, 0.0, float(10.0 ** (3 + parameter % 36))])
    return out


edits = st.lists(st.tuples(st.sampled_from(KINDS), st.integers(0, 10**6), st.integers(0, 10**6)),
                 min_size=1, max_size=4)


@settings(max_examples=25, deadline=None, database=None, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                                 HealthCheck.too_slow])
@given(edits=edits)
def test_degenerate_grooms_retarget_or_are_refused_by_code(toy_a, toy_b, strands, edits):
    hair = Hair.from_strands(edited(strands, edits))
    try:
        inputs = canonical_source(toy_a, hair, source_units="m", hair_units="m")
        adaptable = preprocess(inputs.source, inputs.hair, PreprocessOptions(guides=GUIDES),
                               input_report=inputs.report)
        result = retarget(adaptable, toy_b, RetargetOptions(max_iterations=ITERATIONS))
    except InputError as error:
        assert error.code in REFUSALS, (error.code, error.problem)
        if error.code == STRAY_STRANDS:
            assert any(kind == "stray" for kind, _, _ in edits)
        return
    assert not any(kind == "stray" for kind, _, _ in edits)
    out = result.hair
    np.testing.assert_array_equal(out.offsets, hair.offsets)
    assert np.isfinite(out.points).all()
    at_root = hair.at_root
    roots = out.points[hair.offsets[:-1]][hair.strand_of]
    assert np.abs(out.points[at_root] - roots[at_root]).max() <= 1e-9
    welded = np.flatnonzero(hair.short_segments)
    assert (np.linalg.norm(out.points[welded + 1] - out.points[welded], axis=1) <= 1e-6).all()
    assert result.metrics["penetrating_particles"] == 0
    assert result.metrics["root_to_target_max"] < 1e-9
    assert np.isfinite([result.metrics[name] for name in ("mean_segment_angle_rad", "max_segment_angle_rad",
                                                          "mean_bend_error_rad", "energy_total_per_particle")]).all()
