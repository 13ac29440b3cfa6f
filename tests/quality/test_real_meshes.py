"""Hairline edits on real character meshes (issue 11, item 9).

Average female -> heavy male as busts the way game and scan characters come: eyes and teeth
as separate closed shells, the body cut open at the chest, open eye sockets and three
non-manifold edges (:func:`~hairport.solver.synthetic.makehuman.bust.build_bust`), with a
groom whose strands sit 2-5 mm off the skin. Every hairline preset retargets as on the
plain bodies.
"""

import numpy as np
import pytest

from hairport.solver import pipeline
from hairport.solver.hairline.edit import hairline_edit
from hairport.solver.hairline.presets import PRESETS
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.mesh.shells import shell_labels
from hairport.solver.synthetic.makehuman import build_preset
from hairport.solver.synthetic.makehuman.bust import build_bust
from tests.solver.hairline.real_meshes import LIFT_M, lifted_groom, subdivided

#: the bust's density change may differ from the plain body's by this much (Table 3's L1)
L1_TOLERANCE = 1e-3


@pytest.fixture(scope="module")
def runs():
    plain = build_preset("average-female"), build_preset("heavy-male")
    busts = tuple(build_bust(name, open_eyes=True, fins=3) for name in ("average-female", "heavy-male"))
    hair = lifted_groom(plain[0], 300, 8)
    results = {}
    for kind, (source, target) in (("plain", plain), ("bust", busts)):
        adaptable = pipeline.preprocess(source, hair)
        results[kind] = adaptable, {
            name: pipeline.retarget(adaptable, target, pipeline.RetargetOptions(workers=1,
                                                                                 hairline=hairline_edit(preset=name)))
            for name in PRESETS
        }
    return hair, busts, results


def test_the_groom_sits_off_the_skin(runs):
    hair, (source, _), _ = runs
    distance = MeshQuery(source.vertices, source.faces).signed_distance(hair.points[hair.roots]).distance
    assert LIFT_M[0] - 1e-6 < distance.min() and distance.max() < LIFT_M[1] + 1e-6


def test_the_roots_are_anchored_on_the_skin(runs):
    hair, (source, _), results = runs
    adaptable = results["bust"][0]
    labels = shell_labels(source.faces)
    skin = np.argmax(np.bincount(labels))
    assert (labels[adaptable.anchors.face[hair.roots]] == skin).all()


@pytest.mark.parametrize("name", PRESETS)
def test_every_preset_retargets_on_the_bust(runs, name):
    hair, (_, target), results = runs
    result = results["bust"][1][name]
    metrics = result.metrics
    assert metrics["penetrating_particles"] == 0
    assert metrics["root_to_target_max"] <= 1e-12
    edit = metrics["hairline"]
    assert edit["converged"] and edit["roots_moved"] > 0 and result.relocation.travel.max() > 0.005
    # the roots lie on the skin shell and on no eye, tooth or fin
    labels = shell_labels(target.faces)
    skin = labels == np.argmax(np.bincount(labels))
    roots = result.hair.points[hair.roots]
    on_skin = MeshQuery(target.vertices, target.faces[skin]).signed_distance(roots)
    assert np.abs(on_skin.distance).max() < 1e-9
    nearest = MeshQuery(target.vertices, target.faces).signed_distance(roots)
    assert skin[nearest.faces].all()
    # the same density change as on the plain bodies
    plain = results["plain"][1][name].metrics["hairline"]
    assert edit["density_change_l1"] == pytest.approx(plain["density_change_l1"], abs=L1_TOLERANCE)
    assert edit["scalp_faces"] == plain["scalp_faces"]


def test_a_finer_mesh_takes_the_same_edit(runs):
    """The bust subdivided 1-to-4 (41,620 faces): the head patch keeps its size in meters (12
    rings instead of 6) and the widow's peak retargets as on the bust."""
    hair, busts, results = runs
    source, target = (subdivided(bust) for bust in busts)
    adaptable = pipeline.preprocess(source, hair)
    result = pipeline.retarget(adaptable, target, pipeline.RetargetOptions(
        workers=1, hairline=hairline_edit(preset="widows-peak")))
    assert result.metrics["penetrating_particles"] == 0
    assert result.metrics["root_to_target_max"] <= 1e-12
    edit, coarse = result.metrics["hairline"], results["bust"][1]["widows-peak"].metrics["hairline"]
    assert edit["converged"] and edit["scalp_faces"] > 3 * coarse["scalp_faces"]
    assert edit["density_change_l1"] == pytest.approx(coarse["density_change_l1"], abs=0.005)
