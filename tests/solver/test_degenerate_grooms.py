"""Degenerate pieces of otherwise good grooms through preprocess and retarget (solver/model/degenerate.py).

One degenerate strand among the 300 of a long toy groom (inserted in the middle, at strand 150): the
retarget succeeds, the degenerate piece ends where its kind says, the other strands end where they do
without it, no particle is inside the target, and the input report names the piece.
"""

import numpy as np
import pytest

from hairport.solver.inputs import canonical_source
from hairport.solver.model.degenerate import STRAY_STRANDS
from hairport.solver.model.errors import InputError, PenetrationRemaining
from hairport.solver.model.hair import EMPTY_HAIR, Hair
from hairport.solver.options import RetargetOptions
from hairport.solver.pipeline import preprocess, retarget
from hairport.solver.synthetic.groom import generate_groom

#: where the degenerate strand goes, and the strand it copies (kinds made from another strand)
AT, COPIED = 150, 40
METHODS = ("multiscale", "global")
#: the other strands of a groom with a collapsed strand end exactly where they end without it (the strand
#: is no guide and nobody's neighbour); measured 0 and 8e-15 m (the distance grid covers one more point)
UNCHANGED_M = 1e-9


@pytest.fixture(scope="module")
def strands(toy_a):
    hair = generate_groom(toy_a, "long", 300, 16, seed=3)
    return [hair.strand(s).copy() for s in range(hair.n_strands)]


def run(source, target, hair: Hair, method: str = "multiscale", **options):
    """The canonical inputs (units given) and the retarget of ``hair``."""
    inputs = canonical_source(source, hair, source_units="m", hair_units="m")
    adaptable = preprocess(inputs.source, inputs.hair, input_report=inputs.report)
    return inputs, retarget(adaptable, target, RetargetOptions(method=method, **options))


@pytest.fixture(scope="module")
def base(toy_a, toy_b, strands):
    """The groom's result without a degenerate strand, per method."""
    return {method: run(toy_a, toy_b, Hair.from_strands(strands), method)[1] for method in METHODS}


def with_strand(strands: list[np.ndarray], extra: np.ndarray) -> Hair:
    return Hair.from_strands(strands[:AT] + [extra] + strands[AT:])


def others(hair: Hair, points: np.ndarray) -> np.ndarray:
    """``points`` without the inserted strand's rows."""
    keep = np.ones(hair.n_particles, dtype=bool)
    keep[hair.offsets[AT]:hair.offsets[AT + 1]] = False
    return points[keep]


def collapsed_kinds(strands) -> dict[str, np.ndarray]:
    root = strands[AT][0]
    return {
        "root repeated": np.repeat(root[None], 16, axis=0),
        "at the origin": np.zeros((16, 3)),  # a damaged file's zeros; its root is 1.15 m off the body
        "1e-12 m segments": root + 1e-12 * np.arange(16)[:, None] * np.array([0.6, 0.8, 0.0]),
    }


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("kind", ["root repeated", "at the origin", "1e-12 m segments"])
def test_a_collapsed_strand_stays_on_its_moved_root_and_changes_nothing_else(toy_a, toy_b, strands, base, method, kind):
    hair = with_strand(strands, collapsed_kinds(strands)[kind])
    inputs, result = run(toy_a, toy_b, hair, method)
    own = result.hair.points[hair.offsets[AT]:hair.offsets[AT + 1]]
    assert np.abs(own - own[0]).max() <= 1e-9  # every point on the root ...
    assert result.metrics["root_to_target_max"] < 1e-9  # ... which is where the target puts it
    assert np.isfinite(result.hair.points).all()
    moved = np.linalg.norm(others(hair, result.hair.points) - base[method].hair.points, axis=1)
    assert moved.max() <= UNCHANGED_M
    assert result.metrics["penetrating_particles"] == 0 and not result.inside.any()
    assert result.solve.iterations == base[method].solve.iterations
    report = inputs.report["degenerate"]
    assert report["collapsed_strands"] == {"count": 1, "strands": [AT]}
    assert any(note.startswith("1 of 301 strands have zero length") and f"strand(s) {AT})" in note
               for note in inputs.warnings)
    assert result.metrics["input"]["warnings"] == list(inputs.warnings)
    assert np.isfinite([result.metrics[name] for name in ("mean_segment_angle_rad", "max_bend_error_rad",
                                                          "energy_total_per_particle")]).all()


@pytest.mark.parametrize("method", METHODS)
def test_a_duplicate_strand_stays_with_its_twin(toy_a, toy_b, strands, base, method):
    hair = with_strand(strands, strands[COPIED].copy())
    inputs, result = run(toy_a, toy_b, hair, method)
    twin = result.hair.points[hair.offsets[AT]:hair.offsets[AT + 1]]
    original = result.hair.points[hair.offsets[COPIED]:hair.offsets[COPIED + 1]]
    # Eq. 9 gives the twin (distance 0) the whole weight: bounded rows, and the pair stays together
    assert np.linalg.norm(twin - original, axis=1).max() < 1e-3
    moved = np.linalg.norm(others(hair, result.hair.points) - base[method].hair.points, axis=1)
    # measured: 0 (multi-scale, the twin is no guide) and 1.95 mm / 1e-5 m mean (global: a new neighbour)
    assert moved.max() < 3e-3 and moved.mean() < 2e-5
    assert result.metrics["penetrating_particles"] == 0
    assert inputs.report["degenerate"]["duplicate_strands"] == {"count": 1, "strands": [AT]}
    assert any(f"repeat an earlier strand point for point ({AT})" in note for note in inputs.warnings)


@pytest.mark.parametrize("method", METHODS)
def test_a_strand_of_two_points_is_an_ordinary_strand(toy_a, toy_b, strands, base, method):
    hair = with_strand(strands, strands[COPIED][:2].copy())
    inputs, result = run(toy_a, toy_b, hair, method)
    own = result.hair.points[hair.offsets[AT]:hair.offsets[AT + 1]]
    source_length = np.linalg.norm(np.diff(strands[COPIED][:2], axis=0))
    assert 0.5 * source_length < np.linalg.norm(own[1] - own[0]) < 2.0 * source_length
    moved = np.linalg.norm(others(hair, result.hair.points) - base[method].hair.points, axis=1)
    assert moved.max() < 1e-3 and moved.mean() < 2e-5  # measured 0.37 mm / 5.5e-6 m: one more strand
    assert result.metrics["penetrating_particles"] == 0
    assert inputs.warnings == () and inputs.report["degenerate"]["collapsed_strands"]["count"] == 0


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("where", [0, 6, 15])
def test_a_repeated_point_keeps_its_segment_at_zero_length(toy_a, toy_b, strands, base, method, where):
    """A point repeated at the root, inside and at the tip of strand 100: the repeat is welded to its
    twin (its segment has no direction: Eq. 7's 2 / l^2 made the Hessian singular), everything else ends
    where it ends without the repeat."""
    changed = list(strands)
    changed[100] = np.insert(strands[100], where, strands[100][where], axis=0)
    hair = Hair.from_strands(changed)
    inputs, result = run(toy_a, toy_b, hair, method)
    repeat = hair.offsets[100] + where
    assert np.linalg.norm(result.hair.points[repeat + 1] - result.hair.points[repeat]) < 1e-9
    keep = np.ones(hair.n_particles, dtype=bool)
    keep[repeat + 1] = False
    moved = np.linalg.norm(result.hair.points[keep] - base[method].hair.points, axis=1)
    # measured up to 1.6 mm (the repeat's Eq. 10-11 rows count twice), 0 for a repeated root
    assert moved.max() < (1e-9 if where == 0 else 3e-3) and moved.mean() < 3e-5
    assert result.metrics["penetrating_particles"] == 0
    assert inputs.report["degenerate"]["zero_length_segments"] == {"count": 1, "strand_count": 1, "strands": [100]}


def test_a_collapsed_strand_follows_its_root_in_the_baselines_too(toy_a, toy_b, strands):
    hair = with_strand(strands, collapsed_kinds(strands)["root repeated"])
    for method in ("root-translate", "affine-translate+pushout"):
        _, result = run(toy_a, toy_b, hair, method)
        own = result.hair.points[hair.offsets[AT]:hair.offsets[AT + 1]]
        assert np.abs(own - own[0]).max() <= 1e-9, method
        assert np.isfinite(result.hair.points).all()


@pytest.mark.parametrize("shift", [1e3, 3e38])
def test_a_stray_strand_is_refused_by_name_before_anything_runs(toy_a, strands, shift):
    hair = with_strand(strands, strands[COPIED] + np.array([shift, 0.0, 0.0]))
    for stage in (lambda: canonical_source(toy_a, hair), lambda: preprocess(toy_a, hair)):
        with pytest.raises(InputError) as refused:
            stage()
        assert refused.value.code == STRAY_STRANDS
        assert "1 of 301 strands" in refused.value.problem and f"strand(s) {AT}:" in refused.value.problem


def test_a_groom_of_collapsed_strands_only_is_empty(toy_a, strands):
    hair = Hair.from_strands([strand[:1].repeat(4, axis=0) + 1e-9 * np.arange(4)[:, None] for strand in strands[:20]])
    with pytest.raises(InputError) as refused:
        preprocess(toy_a, hair)
    assert refused.value.code == EMPTY_HAIR and "20" in refused.value.problem


def test_a_collapsed_strand_goes_with_its_relocated_root(toy_a, toy_b):
    """Sec. 6's hairline edit moves the roots: a collapsed strand's points go with its root."""
    from hairport.solver.hairline.edit import HairlineEdit

    fringe = generate_groom(toy_a, "fringe", 300, 12, seed=3)
    fringe_strands = [fringe.strand(s) for s in range(fringe.n_strands)]
    hair = with_strand(fringe_strands, np.repeat(fringe_strands[AT][:1], 12, axis=0))
    _, result = run(toy_a, toy_b, hair, hairline=HairlineEdit(preset="receding", amount=0.5))
    own = result.hair.points[hair.offsets[AT]:hair.offsets[AT + 1]]
    assert result.relocation.travel[AT] > 1e-4  # its root moved (0.45 mm)
    assert np.abs(own - result.relocation.roots[AT]).max() <= 1e-9
    assert result.metrics["penetrating_particles"] == 0


@pytest.mark.parametrize("zeroed", [(0.3, 0.7), (0.48, 0.52), (0.05, 0.95)])
def test_an_alembic_file_whose_middle_reads_as_zeros_is_refused_or_retargets(toy_a, toy_b, strands, zeroed):
    """A damaged .abc (its middle bytes zero): read, its strands at the origin are collapsed (carried on
    their roots) or partly zero, and the groom retargets, the units given or inferred, or is refused because a
    strand that jumps to the origin and back passes through the body (penetration_remaining)."""
    from hairport.solver.io.hair import hair_to_bytes, read_hair_bytes_report

    data = bytearray(hair_to_bytes(Hair.from_strands(strands), "abc"))
    lo, hi = (int(share * len(data)) for share in zeroed)
    data[lo:hi] = bytes(hi - lo)
    try:
        hair = read_hair_bytes_report(bytes(data), "abc", source="cut.abc").hair
    except InputError as error:  # a reader that sees the damage refuses it by its code
        assert error.code and error.problem
        return
    assert hair.collapsed.sum() >= 10 and (hair.points == 0).all(axis=1).any()  # measured 11-283 at the origin
    for units in ("m", None):
        inputs = canonical_source(toy_a, hair, source_units=units, hair_units=units)
        adaptable = preprocess(inputs.source, inputs.hair, input_report=inputs.report)
        try:
            result = retarget(adaptable, toy_b)
        except PenetrationRemaining as error:
            assert error.problem.startswith("segments of hair still pass through the target body")
            continue
        assert np.isfinite(result.hair.points).all() and result.metrics["penetrating_particles"] == 0
        assert result.metrics["crossing_segments"]["count"] == 0
        at_root = hair.at_root
        roots = result.hair.points[hair.offsets[:-1]][hair.strand_of]
        assert np.abs(result.hair.points[at_root] - roots[at_root]).max() <= 1e-9
        assert inputs.report["degenerate"]["collapsed_strands"]["count"] == hair.collapsed.sum()


def test_a_strand_far_from_the_groom_is_retargeted_without_neighbours(toy_a, toy_b, strands, base):
    """1.5 m off the head (not stray: 3.7 groom sizes): its particles are farther than two groom sizes from
    every other strand, so they have no Eq. 10 rows (adaptation/source/neighbours.py) and pull no strand."""
    hair = with_strand(strands, strands[COPIED] + np.array([1.5, 0.0, 0.0]))
    inputs, result = run(toy_a, toy_b, hair, "global")
    moved = np.linalg.norm(others(hair, result.hair.points) - base["global"].hair.points, axis=1)
    assert moved.max() < 2e-3  # measured 0.7 mm (one more guide-sized strand); 11 cm while its rows pulled
    assert np.isfinite(result.hair.points).all() and result.metrics["penetrating_particles"] == 0
    assert any("roots sit more than 1 mm off the source body" in note for note in inputs.warnings)
