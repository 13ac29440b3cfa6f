"""A -> B retargeting quality against the baselines (issue 2's acceptance numbers).

Average female -> heavy male: a much larger head, neck and shoulders, where the naive
transfers penetrate the body by thousands of particles. Grooms with 3-5 mm segments.
"""

import pytest

from hairport.solver import pipeline
from hairport.solver.adaptation.problem.spacing import EVEN_SPACING_WEIGHT
from hairport.solver.baselines import BASELINE_METHODS
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import PRESETS, build_character

EPS_C = 5e-4
#: the final QP's constraints hold to OSQP's tolerance; exact distances may fall short by this (m)
CLEARANCE_TOLERANCE = 1e-5
GROOMS = {"fringe": (60, 64), "long": (60, 80)}


@pytest.fixture(scope="module")
def bodies():
    return build_character(PRESETS["average-female"]), build_character(PRESETS["heavy-male"])


@pytest.fixture(scope="module", params=sorted(GROOMS))
def case(request, bodies):
    source, target = bodies
    strands, particles = GROOMS[request.param]
    hair = generate_groom(source, request.param, strands, particles, seed=0)
    adaptable = pipeline.preprocess(source, hair)
    ours = pipeline.retarget(adaptable, target)
    baselines = {
        method: pipeline.retarget(adaptable, target, pipeline.RetargetOptions(method=method)).metrics
        for name in BASELINE_METHODS
        for method in (name, f"{name}+pushout")
    }
    return request.param, hair, ours, baselines, target


def test_no_particle_inside_and_clearance_kept(case):
    _, hair, ours, _, target = case
    distance = MeshQuery(target.vertices, target.faces).signed_distance(ours.hair.points[~hair.is_root]).distance
    assert (distance < 0).sum() == 0
    assert distance.min() >= EPS_C - CLEARANCE_TOLERANCE


def test_roots_on_the_target_surface(case):
    _, _, ours, _, _ = case
    assert ours.metrics["root_to_surface_max"] <= 1e-5
    assert ours.metrics["root_to_target_max"] <= 1e-12


def test_interstrand_error_lower_than_every_non_rigid_baseline(case):
    """Eq. 10 is translation invariant, so plain global translation scores 0 by construction
    (while putting thousands of particles inside the body); every other baseline is beaten."""
    _, _, ours, baselines, _ = case
    assert baselines["global-translate"]["penetrating_particles"] > 1000
    for method, metrics in baselines.items():
        if method != "global-translate":
            assert ours.metrics["interstrand_error_m"] < metrics["interstrand_error_m"], method


def test_segment_angles_lower_than_every_pushed_out_baseline(case):
    _, _, ours, baselines, _ = case
    for method, metrics in baselines.items():
        if method.endswith("+pushout"):
            assert metrics["penetrating_particles"] == 0
            assert ours.metrics["mean_segment_angle_rad"] < metrics["mean_segment_angle_rad"], method


#: issue 2 asked for 0.1 rad; long hair over the much larger shoulders measured 0.106-0.116 with the
#: paper's initial transfer, 0.084 with the shape carry (issue 16; docs/fidelity.md)
ANGLE_BOUND_RAD = {"fringe": 0.1, "long": 0.1}


def test_mean_segment_angle_within_bound(case):
    style, _, ours, _, _ = case
    assert ours.metrics["mean_segment_angle_rad"] <= ANGLE_BOUND_RAD[style]


#: issue 16: each segment's length over its strand's whole-length ratio, p5 and p95, within this band
IN_STRAND_BAND = (0.8, 1.25)


def test_the_spacing_term_keeps_particles_evenly_spaced_and_bends_where_the_papers_method_bunches_them(case):
    """The paper's method (no spacing term, no shape carry) bunches and stretches segments within
    strands on this pair and kinks strands in the collapsed ones; the spacing term at its even-spacing
    weight (with the default shape carry) keeps every segment's share of its strand within the band
    and the bends twice as close to the source's."""
    _, hair, _, _, target = case
    adaptable = pipeline.preprocess(build_character(PRESETS["average-female"]), hair)
    paper = pipeline.retarget(adaptable, target, pipeline.RetargetOptions(spacing=0.0, carry=0.0))
    ours = pipeline.retarget(adaptable, target, pipeline.RetargetOptions(spacing=EVEN_SPACING_WEIGHT))
    low, high = IN_STRAND_BAND
    bunched = paper.metrics["segment_length_ratio_in_strand"]
    assert bunched["p5"] < low or bunched["p95"] > high, bunched
    within = ours.metrics["segment_length_ratio_in_strand"]
    assert low <= within["p5"] and within["p95"] <= high, within
    assert ours.metrics["mean_bend_error_rad"] < 0.5 * paper.metrics["mean_bend_error_rad"]
    assert paper.metrics["penetrating_particles"] == ours.metrics["penetrating_particles"] == 0
