"""Hair of one preview view: samples along the segments, hidden behind the body, blended nearest first, lit."""

import numpy as np

from hairport.solver.render.strands import (
    AMBIENT,
    LIGHT_VIEW,
    SAMPLE_OPACITY,
    VISIBILITY_TOLERANCE_M,
    hair_layer,
    shade_segments,
)

AXES = (np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]))
RED, BLUE = np.array([200.0, 0.0, 0.0]), np.array([0.0, 0.0, 200.0])


def layer(pixels, depths, colors, surface, compiled=True):
    """hair_layer of strands given in pixels (each (P, 2)), depths (each (P,)) and one colour each."""
    pixel = np.concatenate(pixels).astype(float)
    depth = np.concatenate(depths).astype(float)
    counts = np.array([len(p) for p in pixels])
    points = np.column_stack([pixel[:, 0] * 1e-3, -pixel[:, 1] * 1e-3, depth])  # world: x right, y up
    base = np.repeat(np.array(colors, dtype=float), counts, axis=0)
    return hair_layer(points, counts, base, pixel, depth, AXES, surface, compiled=compiled)


def test_a_segment_covers_each_pixel_of_its_line_once():
    surface = np.full((40, 80), -np.inf)
    color, alpha = layer([np.array([[10.3, 20.0], [50.3, 20.0]])], [np.zeros(2)], [RED], surface)
    covered = np.argwhere(alpha > 0)
    assert set(covered[:, 0]) == {20} and (covered[:, 1].min(), covered[:, 1].max()) == (10, 50)
    assert len(covered) == 41 and np.allclose(alpha[alpha > 0], SAMPLE_OPACITY)
    assert color[20, 30, 0] > 10 * max(color[20, 30, 1], color[20, 30, 2])  # its own colour (and a little sheen)


def test_the_body_hides_what_lies_behind_it_beyond_the_tolerance():
    strand = [np.array([[5.0, 10.0], [35.0, 10.0]])]
    surface = np.full((20, 40), -np.inf)
    surface[:, 20:] = 0.05  # the body, 5 cm in front of the strand, over the right half
    _, alpha = layer(strand, [np.zeros(2)], [RED], surface)
    assert alpha[10, 5:20].all() and not alpha[10, 20:].any()
    surface[:, 20:] = 0.5 * VISIBILITY_TOLERANCE_M  # skin just in front: roots and hair lying on it show
    _, alpha = layer(strand, [np.zeros(2)], [RED], surface)
    assert alpha[10, 5:36].all()


def test_where_strands_cross_the_nearer_colours_the_pixel():
    surface = np.full((40, 40), -np.inf)
    across = np.array([[5.0, 20.0], [35.0, 20.0]])
    down = np.array([[20.0, 5.0], [20.0, 35.0]])
    for near_first, expected in ((True, 0), (False, 2)):
        depths = [np.full(2, 0.1), np.zeros(2)] if near_first else [np.zeros(2), np.full(2, 0.1)]
        color, alpha = layer([across, down], depths, [RED, BLUE], surface)
        assert alpha[20, 20] > alpha[20, 10]  # two samples: more opaque
        assert np.argmax(color[20, 20]) == expected
        assert color[20, 20, expected] > 20 * color[20, 20, 2 - expected]


def test_hair_across_the_light_is_brighter_than_along_it():
    light = LIGHT_VIEW / np.linalg.norm(LIGHT_VIEW)
    across = np.cross(light, [0.0, 0.0, 1.0])
    tangents = np.stack([light, across / np.linalg.norm(across)])
    lit = shade_segments(tangents, np.full((2, 3), 100.0), AXES)
    assert np.allclose(lit[0], 100.0 * AMBIENT, atol=1.0)  # along the light: ambient only (and no sheen)
    assert (lit[1] > 1.8 * lit[0]).all()


def random_strands(rng, n_strands=40, per_strand=7, size=60):
    """Strands partly off a ``size`` x ``size`` image, with their depths and colours."""
    pixels = [rng.uniform(-10, size + 10, (per_strand, 2)) for _ in range(n_strands)]
    depths = [rng.uniform(-0.05, 0.05, per_strand) for _ in range(n_strands)]
    return pixels, depths, rng.uniform(0, 255, (n_strands, 3))


def banded_surface(size=60):
    """A band of body that hides the samples behind it."""
    surface = np.full((size, size), -np.inf)
    surface[20:40] = 0.0
    return surface


def test_chunks_of_samples_draw_the_same_picture(monkeypatch):
    from hairport.solver.render import strands

    pixels, depths, colors = random_strands(np.random.default_rng(0))
    surface = banded_surface()
    whole = layer(pixels, depths, colors, surface, compiled=False)
    monkeypatch.setattr(strands, "CHUNK_SAMPLES", 50)  # tens of chunks of a few segments
    chunked = layer(pixels, depths, colors, surface, compiled=False)
    assert np.allclose(whole[0], chunked[0], atol=1e-3) and np.array_equal(whole[1], chunked[1])
    assert 0 < (whole[1] > 0).mean() < 1 and not (whole[1][25:35] > 0).all()


def test_the_compiled_splat_draws_the_reference_picture():
    for seed in range(3):
        pixels, depths, colors = random_strands(np.random.default_rng(seed), n_strands=60, per_strand=6)
        surface = banded_surface()
        compiled = layer(pixels, depths, colors, surface)
        reference = layer(pixels, depths, colors, surface, compiled=False)
        assert np.array_equal(compiled[0], reference[0]) and np.array_equal(compiled[1], reference[1])
        assert 0.2 < (compiled[1] > 0).mean() < 0.95 and not (compiled[1][25:35] > 0).all()  # some of it hidden


def test_past_the_sample_budget_segments_are_sampled_more_sparsely(monkeypatch):
    from hairport.solver.render import strands

    surface = np.full((10, 240), -np.inf)
    strand = [np.array([[20.0, 5.0], [220.0, 5.0]])]
    assert (layer(strand, [np.zeros(2)], [RED], surface)[1] > 0).sum() == 201
    monkeypatch.setattr(strands, "MAX_SAMPLES", 50)  # 200 pixels long: one sample every 4 pixels
    _, alpha = layer(strand, [np.zeros(2)], [RED], surface)
    assert np.array_equal(np.flatnonzero(alpha[5] > 0), np.arange(20, 221, 4))
