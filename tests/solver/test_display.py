"""The display's decimation, wire format and scenes (hairport.solver.display)."""

import numpy as np
import pytest

from hairport.solver import display
from hairport.solver.model.errors import InputError


def decimate_reference(offsets, strand_ids, stride):
    """Every stride-th particle of each strand and its tip, one strand at a time."""
    particles, starts = [], [0]
    for strand in strand_ids:
        first, stop = offsets[strand], offsets[strand + 1]
        picked = list(range(first, stop, stride))
        if picked[-1] != stop - 1:
            picked.append(stop - 1)
        particles += picked
        starts.append(len(particles))
    return np.array(particles), np.array(starts)


@pytest.mark.parametrize("stride", [1, 2, 3, 7, 50])
def test_decimation_matches_the_reference_and_keeps_roots_and_tips(stride):
    rng = np.random.default_rng(stride)
    offsets = np.concatenate([[0], np.cumsum(rng.integers(2, 40, size=60))])
    strand_ids = np.sort(rng.choice(60, size=25, replace=False))
    particles, starts = display.decimate(offsets, strand_ids, stride)
    expected_particles, expected_starts = decimate_reference(offsets, strand_ids, stride)
    np.testing.assert_array_equal(particles, expected_particles)
    np.testing.assert_array_equal(starts, expected_starts)
    np.testing.assert_array_equal(particles[starts[:-1]], offsets[strand_ids])
    np.testing.assert_array_equal(particles[starts[1:] - 1], offsets[strand_ids + 1] - 1)


def test_the_automatic_plan_fits_the_budget_and_prefers_whole_strands():
    offsets = np.arange(0, 1_000_001, 50)  # 20,000 strands of 50
    strand_ids, stride = display.plan_display(offsets, 200_000)
    drawn = display.vertices_per_strand(np.diff(offsets)[strand_ids], stride).sum()
    assert stride == 1 and len(strand_ids) == 4000 and drawn == 200_000
    assert strand_ids[0] == 0 and strand_ids[-1] == 19_999  # spread over the whole groom
    few, step = display.plan_display(offsets, 20_000)  # under MIN_AUTO_STRANDS whole strands: particles go first
    assert len(few) >= display.MIN_AUTO_STRANDS and step > 1
    assert display.vertices_per_strand(np.diff(offsets)[few], step).sum() <= 20_000


def test_an_asked_strand_count_or_stride_is_kept():
    offsets = np.arange(0, 100_001, 100)
    strand_ids, stride = display.plan_display(offsets, 10_000, strands=50)
    assert len(strand_ids) == 50 and stride == 1
    strand_ids, stride = display.plan_display(offsets, 10_000, stride=10)
    assert stride == 10 and len(strand_ids) == 10_000 // 11
    strand_ids, stride = display.plan_display(offsets, strands=3, stride=4)
    assert len(strand_ids) == 3 and stride == 4


@pytest.mark.parametrize("kwargs, words", [
    ({"stride": 0}, "stride 0"), ({"stride": display.MAX_STRIDE + 1}, "outside"), ({"strands": 0}, "at least 1"),
    ({"max_vertices": 0}, "budget"), ({"max_vertices": display.MAX_DISPLAY_VERTICES + 1}, "budget"),
])
def test_absurd_plans_are_refused(kwargs, words):
    with pytest.raises(InputError, match=words) as error:
        display.plan_display(np.arange(0, 101, 10), **kwargs)
    assert error.value.code == "bad_display"


def test_a_plan_over_the_vertex_limit_is_refused():
    offsets = np.arange(0, 3_000_001, 1000)
    with pytest.raises(InputError, match="at most"):
        display.plan_display(offsets, strands=3000, stride=1)


def test_the_wire_format_round_trips_aligned_arrays():
    arrays = {"positions": np.arange(9, dtype=np.float32).reshape(3, 3), "starts": np.array([0, 3], np.uint32),
              "inside": np.array([0, 1, 0], np.uint8)}
    payload = display.encode({"layer": "result"}, arrays)
    assert payload[:4] == b"HPD1"
    header, decoded = display.decode(payload)
    assert header["layer"] == "result"
    for name, array in arrays.items():
        np.testing.assert_array_equal(decoded[name], array)
        assert decoded[name].dtype == array.dtype
    length = int(np.frombuffer(payload[4:8], "<u4")[0])
    assert (8 + length) % display.ALIGNMENT == 0
    with pytest.raises(ValueError, match="dtype"):
        display.encode({}, {"bad": np.zeros(2, np.float64)})


def test_strands_payload_carries_inside_flags_and_colours_of_the_drawn_particles():
    points = np.arange(30, dtype=np.float64).reshape(10, 3)
    offsets = np.array([0, 4, 10])
    inside = np.zeros(10, bool)
    inside[[2, 9]] = True
    color = np.linspace(0, 1, 30).reshape(10, 3)
    scene = display.scene_arrays(points, offsets, inside, color, np.eye(3), np.array([[0, 1, 2]]), np.eye(3),
                                 {"points": [[0, 0, 0]] * 3, "turning_points": [0, 2]}, {})
    header, arrays = display.decode(display.strands_payload(scene, np.array([0, 1]), 2, "result"))
    assert header["drawn_vertices"] == 7 and header["inside"] == 2 and header["particles"] == 10
    np.testing.assert_array_equal(arrays["positions"], points[[0, 2, 3, 4, 6, 8, 9]].astype(np.float32))
    np.testing.assert_array_equal(arrays["inside"], [0, 1, 0, 0, 0, 0, 1])
    np.testing.assert_array_equal(arrays["color"], display.colors_u8(color)[[0, 2, 3, 4, 6, 8, 9]])
    np.testing.assert_array_equal(arrays["starts"], [0, 3, 7])


def test_scenes_save_and_load_by_member(tmp_path):
    hairline = {"points": [[0.1, 1.6, 0.05], [0.0, 1.7, 0.1], [-0.1, 1.6, 0.05]], "turning_points": [0, 2]}
    scene = display.scene_arrays(np.zeros((4, 3)), np.array([0, 2, 4]), np.array([1, 0, 0, 1], bool), None,
                                 np.eye(3), np.array([[0, 1, 2]]), np.diag([1.0, -1.0, -1.0]), hairline,
                                 {"round": {"points": hairline["points"][::-1], "turning_points": [0, 2]}})
    path = display.save_scene(tmp_path / "scene.npz", scene)
    loaded = display.load_scene(path, ("offsets", "inside"))
    assert set(loaded) == {"offsets", "inside"}
    np.testing.assert_array_equal(np.unpackbits(loaded["inside"], count=4), [1, 0, 0, 1])
    document = display.hairline_json(display.load_scene(path))
    assert document["points"] == hairline["points"] and document["turning_points"] == [0, 2]
    assert document["presets"] == {"round": hairline["points"][::-1]}
    assert document["groom_rotation"] == [[1, 0, 0], [0, -1, 0], [0, 0, -1]]
    (tmp_path / "broken.npz").write_bytes(b"PK\x03\x04 truncated")
    with pytest.raises(InputError, match="cannot be read") as error:
        display.load_scene(tmp_path / "broken.npz")
    assert error.value.code == "bad_scene"


def test_a_scene_keeps_the_wrapped_body_only_when_given(tmp_path):
    hairline = {"points": [[0.1, 1.6, 0.05], [0.0, 1.7, 0.1], [-0.1, 1.6, 0.05]], "turning_points": [0, 2]}
    common = (np.zeros((4, 3)), np.array([0, 2, 4]), np.zeros(4, bool), None, np.eye(3), np.array([[0, 1, 2]]),
              np.eye(3), hairline, {})
    wrapped_vertices = np.arange(15, dtype=np.float64).reshape(5, 3) / 10
    wrapped_faces = np.array([[0, 1, 2], [0, 2, 3], [0, 3, 4]])
    plain = display.save_scene(tmp_path / "plain.npz", display.scene_arrays(*common))
    wrapped = display.save_scene(tmp_path / "wrapped.npz",
                                 display.scene_arrays(*common, wrapped=(wrapped_vertices, wrapped_faces)))
    assert not display.scene_has_wrap(display.load_scene(plain))
    assert display.load_scene(plain, display.WRAPPED_ARRAYS) == {}
    loaded = display.load_scene(wrapped, display.WRAPPED_ARRAYS)
    assert display.scene_has_wrap(loaded) and set(loaded) == set(display.WRAPPED_ARRAYS)
    assert loaded["wrapped_vertices"].dtype == np.float32 and loaded["wrapped_faces"].dtype == np.uint32
    np.testing.assert_allclose(loaded["wrapped_vertices"], wrapped_vertices, atol=1e-7)
    np.testing.assert_array_equal(loaded["wrapped_faces"], wrapped_faces)
    # the body arrays are the target's, whether or not a wrap rides along
    np.testing.assert_array_equal(display.load_scene(wrapped)["body_faces"], [[0, 1, 2]])


def test_colours_are_clipped_and_nan_safe():
    np.testing.assert_array_equal(display.colors_u8(np.array([[0.0, 0.5, 1.0], [-1.0, 2.0, np.nan]])),
                                  [[0, 128, 255], [0, 255, 128]])
    assert display.colors_u8(None) is None


def test_a_lone_character_is_drawn_up_its_given_axis_or_its_longest_extent():
    lying = np.array([[0, 0, 0], [0.3, 0, 0], [0, 0.4, 0], [0, 0, 1.8]])  # a Z-up body in meters
    assert display.display_up(lying, None) == ([0.0, 0.0, 1.0], "longest extent")
    assert display.display_up(lying, "-y") == ([0.0, -1.0, 0.0], "given")


def test_a_drawn_segment_is_crossing_when_it_spans_a_groom_segment_through_the_body():
    points = np.arange(30, dtype=np.float64).reshape(10, 3)
    offsets = np.array([0, 4, 10])
    crossing = np.zeros(10, bool)
    crossing[[1, 5, 8]] = True  # segments 1-2, 5-6 and 8-9 pass through the body
    scene = display.scene_arrays(points, offsets, np.zeros(10, bool), None, np.eye(3), np.array([[0, 1, 2]]),
                                 np.eye(3), {"points": [[0, 0, 0]] * 3, "turning_points": [0, 2]}, {},
                                 crossing=crossing)
    header, arrays = display.decode(display.strands_payload(scene, np.array([0, 1]), 2, "result"))
    # drawn: strand 0 as 0-2-3, strand 1 as 4-6-8-9: 0-2 spans 1-2, 4-6 spans 5-6, 8-9 is 8-9
    np.testing.assert_array_equal(arrays["crossing"], [1, 0, 0, 1, 0, 1, 0])
    assert header["crossing"] == 3
    # at stride 1 every groom segment is drawn: the flags are the groom's
    header, arrays = display.decode(display.strands_payload(scene, np.array([0, 1]), 1, "result"))
    np.testing.assert_array_equal(arrays["crossing"], crossing.astype(np.uint8))
    # a scene without the bits (written before they were kept) draws none
    del scene["crossing"]
    header, arrays = display.decode(display.strands_payload(scene, np.array([0, 1]), 2, "result"))
    assert "crossing" not in arrays and header["crossing"] is None
