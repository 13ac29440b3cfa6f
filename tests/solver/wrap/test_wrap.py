"""Tests for solver/wrap/__init__.py: wrap_body, a source body's topology in a target's shape.

The toy tests run everywhere. The MakeHuman tests (skipped without the assets) wrap
average-female onto the other presets remeshed (:mod:`hairport.solver.synthetic.remesh`), whose
original has the source's topology: wrapped vertex ``i`` should land on preset vertex ``i``.
Their bounds are the measured figures (``bench/wrap.py``, 2 shared cores) with a margin:
onto heavy-male's head remeshed to 20k vertices, a hair region of ~5k vertices wraps in ~3 s
(the goal is 5 s; the bound here is loose for a loaded machine) to a residual of 0.4 mm mean,
1.3 mm p95, with the scalp's vertices 4.2 mm (mean) from the truth and the head and neck's 2.4 mm.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from hairport.solver.body.head_frame import head_frame
from hairport.solver.model.errors import InputError
from hairport.solver.synthetic.groom import generate_groom, scalp_faces
from hairport.solver.synthetic.makehuman import build_preset
from hairport.solver.synthetic.remesh import bust_cut, cut_above, head_cut, remesh
from hairport.solver.wrap import WrapOptions, WrapResult, check_wrap, hair_region, wrap_body
from tests.solver.synthetic.makehuman_fixtures import makehuman_assets

MM = 1e-3
#: the toy's head: vertices above this height (m)
TOY_HEAD_Y = 1.45
#: where a head is in the MakeHuman frame (m): the bad shapes are put there (the start finds them anyway)
HEAD_CENTRE = np.array([0.0, 0.72, 0.0])


def _bad_shapes() -> dict:
    """Meshes centred at the origin that no body wraps onto."""
    return {"sphere": trimesh.creation.icosphere(4, 0.1), "box": trimesh.creation.box((0.2, 0.25, 0.22)),
            "torus": trimesh.creation.torus(0.1, 0.04, 64, 32)}


def test_the_toy_is_wrapped_onto_another_toy_of_another_topology(toys):
    source, _, (vertices, faces) = toys
    result = wrap_body(source.vertices, source.faces, vertices, faces)
    assert isinstance(result, WrapResult)
    assert result.vertices.shape == source.vertices.shape and result.vertices.dtype == np.float64
    assert result.region.all() and result.iterations > 0 and result.seconds > 0
    # measured: 0.15 / 0.56 mm, agreement 1.0
    assert result.residual.symmetric.mean < 0.3 * MM and result.residual.symmetric.p95 < 1.0 * MM
    assert result.residual.coverage == 1.0 and result.residual.agreement > 0.99
    check_wrap(result)


def test_a_whole_toy_onto_a_cut_one_fits_where_the_target_has_surface(toys):
    source, _, (vertices, faces) = toys
    head_v, head_f, _ = cut_above(vertices, faces, 1.5)
    result = wrap_body(source.vertices, source.faces, head_v, head_f)
    assert 0.3 < result.residual.coverage < 0.7  # the body below the cut finds no surface
    assert result.residual.symmetric.p95 < 1.0 * MM
    # the body below follows smoothly: no vertex is thrown far
    assert np.abs(result.vertices - source.vertices).max() < 0.15


@pytest.mark.parametrize("shape", ["sphere", "box", "torus"])
def test_shapes_that_are_not_a_body_are_refused(toys, shape):
    source = toys[0]
    mesh = _bad_shapes()[shape]
    with pytest.raises(InputError) as error:
        wrap_body(source.vertices, source.faces, np.asarray(mesh.vertices) + [0.0, 1.62, 0.0], mesh.faces,
                  source.vertices[:, 1] > TOY_HEAD_Y)
    assert error.value.code == "wrap_failed" and "mm" in str(error.value)


def test_unusable_input_is_refused_by_name(toys):
    source, _, (vertices, faces) = toys
    with pytest.raises(InputError, match="region") as error:
        wrap_body(source.vertices, source.faces, vertices, faces, np.ones(5, bool))
    assert error.value.code == "bad_region"
    with pytest.raises(InputError) as error:
        wrap_body(source.vertices, source.faces, vertices, faces, np.zeros(source.n_vertices, bool))
    assert error.value.code == "bad_region"
    broken = vertices.copy()
    broken[0, 0] = np.nan
    with pytest.raises(InputError) as error:
        wrap_body(source.vertices, source.faces, broken, faces)
    assert error.value.code == "non_finite"
    with pytest.raises(InputError) as error:
        wrap_body(source.vertices, source.faces, vertices, faces + len(vertices))
    assert error.value.code == "bad_mesh"


@pytest.fixture(scope="module")
def makehuman():
    """(source, hair region, scalp vertex ids, head+neck mask, presets by name)."""
    assets = makehuman_assets()
    source = build_preset("average-female", assets)
    frame = head_frame(source)
    hair = generate_groom(source, "long", 500, 20, seed=0)
    region = hair_region(source.vertices, source.faces, hair.points, 0.05)
    scalp = np.unique(source.faces[scalp_faces(source, frame)])
    neck = source.weights[:, source.skeleton.index("neck_01")].toarray().ravel() > 0.5
    presets = {name: build_preset(name, assets) for name in ("heavy-male", "child")}
    return source, region, scalp, frame.head_vertices | neck, presets


def _truth_errors(result, truth, ids) -> np.ndarray:
    return np.linalg.norm(result.vertices[ids] - truth[ids], axis=1)


def test_a_makehuman_body_is_wrapped_onto_another_preset_s_remeshed_head(makehuman):
    source, region, scalp, head_neck, presets = makehuman
    truth = presets["heavy-male"]
    head = head_cut(truth)[0]
    vertices, faces = remesh(head.vertices, head.faces, 20_000, seed=1)
    result = wrap_body(source.vertices, source.faces, vertices, faces, region)
    assert result.seconds < 15.0  # ~3 s measured; the 5 s goal is bench/wrap.py's
    assert result.residual.symmetric.mean < 0.6 * MM and result.residual.symmetric.p95 < 2.0 * MM
    # measured: scalp 4.2 / 8.2 mm (mean / p95), head and neck 2.4 / 7.1 mm; tangential sliding
    # on the smooth skull is the error (a skull cap turned a few degrees about the ears)
    assert _truth_errors(result, truth.vertices, scalp).mean() < 6 * MM
    assert _truth_errors(result, truth.vertices, head_neck).mean() < 3.5 * MM


def test_landmarks_pull_their_points(makehuman):
    source, region, scalp, _, presets = makehuman
    truth = presets["child"]
    vertices, faces = remesh(truth.vertices, truth.faces, 5_000, seed=2)
    chosen = scalp[:: max(1, len(scalp) // 4)][:4]
    landmarks = {f"scalp {i}": (source.vertices[i], truth.vertices[i]) for i in chosen}
    result = wrap_body(source.vertices, source.faces, vertices, faces, region, landmarks)
    assert set(result.landmark_errors) == set(landmarks)
    # held to the end (the default schedule), each lands on its target; released after three steps, they drift
    assert max(result.landmark_errors.values()) < 0.5 * MM
    released = wrap_body(source.vertices, source.faces, vertices, faces, region, landmarks,
                         WrapOptions(landmark_weights=(1.0, 0.5, 0.2, 0.0)))
    assert max(released.landmark_errors.values()) > 2 * MM
    assert result.start.scale == pytest.approx(1.0, abs=0.15)


def test_a_whole_body_onto_a_head_or_a_bust_cut_from_another_preset(makehuman):
    source, region, scalp, _, presets = makehuman
    truth = presets["heavy-male"]
    head = head_cut(truth)[0]
    vertices, faces = remesh(head.vertices, head.faces, 5_000, seed=3)
    whole = wrap_body(source.vertices, source.faces, vertices, faces)  # region: every vertex
    assert 0.2 < whole.residual.coverage < 0.5  # the body below the neck finds no surface: no data there
    assert _truth_errors(whole, truth.vertices, scalp).mean() < 8 * MM
    bust = bust_cut(truth)[0]
    vertices, faces = remesh(bust.vertices, bust.faces, 5_000, seed=3)
    result = wrap_body(source.vertices, source.faces, vertices, faces, region)
    assert result.residual.symmetric.p95 < 2.0 * MM
    assert _truth_errors(result, truth.vertices, scalp).mean() < 6 * MM


@pytest.mark.parametrize("shape", ["sphere", "box", "torus"])
def test_a_makehuman_body_refuses_shapes_that_are_not_a_body(makehuman, shape):
    source, region = makehuman[:2]
    mesh = _bad_shapes()[shape]
    with pytest.raises(InputError) as error:
        wrap_body(source.vertices, source.faces, np.asarray(mesh.vertices) + HEAD_CENTRE, mesh.faces, region)
    assert error.value.code == "wrap_failed"
