"""A target of another topology in a retarget (solver/wrapping.py): the source body wrapped onto it for the
correspondence, the target itself for the contact, and the wrap handed back for reuse."""

import numpy as np
import pytest

from hairport.solver import pipeline
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.errors import InputError, TopologyMismatch
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import PRESETS, build_character
from hairport.solver.synthetic.remesh import remeshed_character
from hairport.solver.wrap import WrapOptions
from hairport.solver.wrapping import content_key, needs_wrap, onto_body, reach_region, wrap_key


@pytest.fixture(scope="module")
def source():
    return build_character(PRESETS["average-female"])


@pytest.fixture(scope="module")
def adaptable(source):
    return pipeline.preprocess(source, generate_groom(source, "short", 200, 12, seed=1))


@pytest.fixture(scope="module")
def remeshed_male():
    return remeshed_character(build_character(PRESETS["heavy-male"]), 5000, seed=4)


def test_the_mode_decides_when_to_wrap(source, remeshed_male):
    assert not needs_wrap(source, source, "auto") and needs_wrap(source, remeshed_male, "auto")
    assert needs_wrap(source, source, "always") and not needs_wrap(source, remeshed_male, "off")
    with pytest.raises(InputError) as error:
        needs_wrap(source, source, "sometimes")
    assert error.value.code == "bad_option" and "auto, always, off" in str(error.value)


def test_the_region_is_what_the_hair_reaches(adaptable):
    region = reach_region(adaptable.source, adaptable.hair)
    vertices = adaptable.source.vertices
    # the head, neck and shoulders the short hair reaches (the body spans 1.77 m below the crown), not the legs
    assert 0.05 * len(vertices) < region.sum() < 0.6 * len(vertices)
    assert vertices[region][:, 1].min() > 0.4 > vertices[:, 1].min() + 1.0 and vertices[region][:, 1].max() == pytest.approx(vertices[:, 1].max())


def test_the_key_changes_with_either_body_the_region_and_the_options(adaptable, remeshed_male):
    source, region = adaptable.source, reach_region(adaptable.source, adaptable.hair)
    key = content_key(source, region, remeshed_male, WrapOptions())
    assert len(key) == 32 and key == content_key(source, region.copy(), remeshed_male, WrapOptions())
    moved = type(remeshed_male)(remeshed_male.vertices + 1e-9, remeshed_male.faces)
    others = {content_key(source, region, moved, WrapOptions()), content_key(source, ~region, remeshed_male, WrapOptions()),
              content_key(source, region, remeshed_male, WrapOptions(inner_iterations=3))}
    assert key not in others and len(others) == 3
    assert wrap_key(adaptable, remeshed_male) == key


def test_strands_move_with_their_roots_onto_the_body(adaptable, remeshed_male):
    hair = adaptable.hair
    lifted = hair.points + np.array([0.0, 0.003, 0.0])  # every strand 3 mm above where it was
    roots = lifted[hair.roots]
    query = MeshQuery(adaptable.source.vertices, adaptable.source.faces)
    points, landed = onto_body(hair, lifted, roots, query)
    assert np.abs(query.signed_distance(landed).distance).max() < 1e-9
    # each strand moved as a whole, by its root's move
    moves = points - lifted
    np.testing.assert_allclose(moves, np.repeat(landed - roots, hair.counts, axis=0))


def test_a_retarget_onto_another_topology_wraps_touches_the_real_body_and_reuses_the_wrap(adaptable, remeshed_male):
    result = pipeline.retarget(adaptable, remeshed_male)
    metrics = result.metrics
    assert metrics["penetrating_particles"] == 0 and metrics["root_to_surface_max"] < 1e-4
    wrap = metrics["wrap"]
    assert wrap["residual_m"]["mean"] < 2e-3 and wrap["fitted_vertices"] > 1000 and "wrap" in result.timings
    assert result.wrapped.key == wrap_key(adaptable, remeshed_male)
    again = pipeline.retarget(adaptable, remeshed_male, wrapped=result.wrapped)
    assert "wrap" not in again.timings and np.array_equal(again.hair.points, result.hair.points)
    with pytest.raises(TopologyMismatch):
        pipeline.retarget(adaptable, remeshed_male, pipeline.RetargetOptions(wrap="off"))
