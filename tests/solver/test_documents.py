"""Hairline curve documents and the dashboard's scene (solver/documents.py)."""

import dataclasses

import numpy as np

from hairport.solver import display, documents, pipeline
from hairport.solver.model.frame import InputFrame
from hairport.solver.synthetic.makehuman import PRESETS, build_character


def test_the_display_scene_holds_the_result_its_inside_flags_and_the_hairlines(female, fringe):
    male = build_character(PRESETS["heavy-male"])
    adaptable = pipeline.preprocess(female, fringe)
    result = pipeline.retarget(adaptable, male, pipeline.RetargetOptions(method="root-translate"))
    scene = documents.display_scene(adaptable, result, male)
    inside = np.unpackbits(scene["inside"], count=fringe.n_particles).astype(bool)
    np.testing.assert_array_equal(inside, pipeline.penetrating_mask(result.hair, male))
    assert inside.sum() == result.metrics["penetrating_particles"] > 0  # the baseline leaves hair inside
    np.testing.assert_allclose(scene["points"], result.hair.points, atol=1e-6)
    np.testing.assert_allclose(scene["body_vertices"], male.vertices, atol=1e-6)
    current = documents.hairline_document(adaptable, male)
    np.testing.assert_allclose(scene["hairline_points"], current["points"], atol=1e-6)
    np.testing.assert_array_equal(scene["hairline_turning"], current["turning_points"])
    widows = documents.hairline_document(adaptable, male, "widows-peak")
    np.testing.assert_allclose(scene[display.scene_preset_array("widows-peak")], widows["points"], atol=1e-6)
    assert display.scene_meta(scene) == {"groom_units": "m", "hairline_error": None}
    assert result.wrapped is None and not display.scene_has_wrap(scene)  # same topology: nothing wrapped kept
    assert not set(display.WRAPPED_ARRAYS) & set(scene)
    # the preset moves the hairline's middle, keeps its ends
    middle = len(current["points"]) // 2
    assert np.linalg.norm(np.subtract(widows["points"][middle], current["points"][middle])) > 1e-3
    np.testing.assert_allclose(widows["points"][0], current["points"][0], atol=1e-6)
    # its crossing bits are the report's; a result the pipeline did not measure gets both sets of bits measured
    crossing = np.unpackbits(scene["crossing"], count=fringe.n_particles).astype(bool)
    assert crossing.sum() == result.metrics["crossing_segments"]["count"] > 0
    unmeasured = documents.display_scene(adaptable, dataclasses.replace(result, inside=None, crossing=None), male)
    for name in ("inside", "crossing"):
        np.testing.assert_array_equal(unmeasured[name], scene[name])


def test_a_curve_document_is_written_in_the_grooms_units_and_axes():
    frame = InputFrame("mm", "z", "-y")
    points = np.array([[0.1, 1.6, 0.05], [0.0, 1.7, 0.09], [-0.1, 1.6, 0.05]])
    document = {"units": "m", "points": points.tolist(), "turning_points": [1]}
    written = documents.curve_document_in_frame(frame, document)
    assert written["units"] == "mm" and written["turning_points"] == [1]
    assert np.allclose(written["points"], frame.axes_out(points) * 1000.0, atol=1e-4)
    # at the canonical document's precision: 0.1 micrometre is 1e-4 mm
    assert all(round(value, 4) == value for point in written["points"] for value in point)


def test_the_scene_of_a_target_of_another_topology_draws_it_with_the_hairline_found_on_its_wrap(female, fringe):
    from hairport.solver.synthetic.remesh import remeshed_character

    target = remeshed_character(build_character(PRESETS["heavy-male"]), 5000, seed=5)
    adaptable = pipeline.preprocess(female, fringe)
    result = pipeline.retarget(adaptable, target, pipeline.RetargetOptions(method="root-translate+pushout"))
    scene = documents.display_scene(adaptable, result, target)
    np.testing.assert_allclose(scene["body_vertices"], target.vertices, atol=1e-6)
    assert display.scene_meta(scene)["hairline_error"] is None
    current = documents.hairline_document(adaptable, result.wrapped.shape)
    np.testing.assert_allclose(scene["hairline_points"], current["points"], atol=1e-6)
    assert len(current["points"]) > 10
    # the wrapped body rides along: the source's faces in the wrap's shape, not the target's mesh
    assert display.scene_has_wrap(scene)
    assert scene["wrapped_vertices"].shape == (result.wrapped.shape.n_vertices, 3) == (female.n_vertices, 3)
    assert scene["wrapped_faces"].shape == female.faces.shape and female.n_vertices != target.n_vertices
    np.testing.assert_array_equal(scene["wrapped_faces"], female.faces)
    np.testing.assert_allclose(scene["wrapped_vertices"], result.wrapped.shape.vertices, atol=1e-5)
