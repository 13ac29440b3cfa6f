"""Penetration-free at any depth (issue 11, item 1).

Average female -> heavy male, a long groom (150 strands x 40) sunk 3 and 6 cm into the
source: into the closed MakeHuman body, and into busts the way game and scan characters
come (eyes and teeth as separate closed shells, cut open at the chest and at the eye
sockets, three non-manifold edges; :func:`~hairport.solver.synthetic.makehuman.bust.build_bust`).
The initial transfer leaves thousands of particles inside, hundreds more than 2 cm deep
(the broad phase used to take them for far outside: 432 and 1,623 stayed inside the closed
body, up to 7.3 cm deep, 456 and 1,663 inside the bust, all with ``converged: true``); the
result has none, roots exact.
"""

import igl
import numpy as np
import pytest

from hairport.solver import pipeline
from hairport.solver.mesh.collision import collision_query
from hairport.solver.model.errors import PenetrationRemaining
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import build_preset
from hairport.solver.synthetic.makehuman.bust import build_bust
from tests.solver.depth_cases import sunk

EPS_C = 5e-4
#: the sunk grooms whose retarget keeps segments through the body: refused
REFUSED = {("closed", 0.06)}
#: the solver meets the clearance to its tolerance (m)
CLEARANCE_TOLERANCE = 1e-5


@pytest.fixture(scope="module")
def bodies():
    return {
        "closed": (build_preset("average-female"), build_preset("heavy-male")),
        "bust": tuple(build_bust(name, open_eyes=True, fins=3) for name in ("average-female", "heavy-male")),
    }


@pytest.fixture(scope="module")
def groom(bodies):
    return generate_groom(bodies["closed"][0], "long", 150, 40, seed=0)


@pytest.mark.parametrize("depth", [0.03, 0.06])
@pytest.mark.parametrize("body", ["closed", "bust"])
def test_a_groom_sunk_into_the_body_comes_out_with_exact_roots(bodies, groom, body, depth):
    """The groom comes out whole: no particle and no segment inside, but 6 cm deep into the closed body, where
    its strands come out stretched (segments up to 8.5 cm) and some still pass through the hands after the
    final check (measured: 31 segments): that result is refused, not reported with them."""
    source, target = bodies[body]
    hair = sunk(groom, depth)
    adaptable = pipeline.preprocess(source, hair)
    if (body, depth) in REFUSED:
        with pytest.raises(PenetrationRemaining) as error:
            pipeline.retarget(adaptable, target)
        assert error.value.problem.startswith("segments of hair still pass through the target body")
        return
    result = pipeline.retarget(adaptable, target)
    assert result.metrics["crossing_segments"]["count"] == 0
    free = ~hair.is_root
    surface = collision_query(target.vertices, target.faces)
    initial = surface.signed_distance(result.initial.points[free]).distance
    assert (initial < 0).sum() > 2000 and (initial < -0.02).sum() > 100, ((initial < 0).sum(), initial.min())
    after = surface.signed_distance(result.hair.points[free]).distance
    # particles the final check moved to clear a segment are outside, not always at the clearance (as pushed ones)
    moved_segments = result.metrics["segments_resolved"]["segments"]
    assert (after < 0).sum() == 0 and after.min() >= (0.0 if moved_segments else EPS_C - CLEARANCE_TOLERANCE)
    # the exact generalized winding number of the whole mesh (eyes, teeth, fins, the open cut) agrees
    assert (igl.winding_number(target.vertices, target.faces, result.hair.points[free]) > 0.5).sum() == 0
    metrics = result.metrics
    assert metrics["penetrating_particles"] == 0
    assert metrics["penetration_resolved"] == {"particles": 0, "deepest_m": 0.0}
    assert metrics["root_to_target_max"] <= 1e-12 and metrics["root_to_surface_max"] <= 1e-12
    assert result.solve.converged
    np.testing.assert_array_equal(result.hair.offsets, hair.offsets)
