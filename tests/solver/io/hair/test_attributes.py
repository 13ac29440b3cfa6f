"""Attributes carried through every format: a chain of conversions keeps points, thickness, colour
and every attribute each format holds, exactly (float32 where the format is float32)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from hairport.solver.io.hair import FORMATS, HairIOWarning, hair_to_bytes, read_hair_bytes_report
from hairport.solver.model.hair import Hair, HairAttribute
from tests.solver.io.hair.samples import helix_hair

CHAIN = ["npz", "usda", "ply", "abc", "usdc", "hair", "npz"]


@pytest.fixture(scope="module")
def groom() -> Hair:
    base = helix_hair(n_strands=9)
    n, s = base.n_particles, base.n_strands
    rng = np.random.default_rng(11)
    exact32 = lambda shape: rng.random(shape).astype(np.float32).astype(np.float64)  # noqa: E731
    attributes = {
        "transparency": HairAttribute(rng.random(n).astype(np.float32), "vertex"),
        "uv": HairAttribute(rng.random((n, 2)).astype(np.float32), "vertex", "texcoord"),
        "groom_group_id": HairAttribute(rng.integers(0, 5, s).astype(np.int32), "strand"),
        "root_uv": HairAttribute(rng.random((s, 2)).astype(np.float32), "strand", "texcoord"),
    }
    color = rng.integers(0, 256, (n, 3)) / 255.0  # 8-bit colours: PLY quantizes to them
    return Hair(base.points.astype(np.float32).astype(np.float64), base.offsets, exact32(n) * 1e-4, color, attributes)


def test_a_chain_of_conversions_keeps_every_attribute_each_format_holds(groom):
    hair, held = groom, dict(groom.attributes)
    for fmt in CHAIN:
        spec = FORMATS[fmt]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", HairIOWarning)
            report = read_hair_bytes_report(hair_to_bytes(hair, fmt), fmt, source=f"g.{fmt}")
        hair = report.hair
        np.testing.assert_array_equal(hair.offsets, groom.offsets)
        np.testing.assert_array_equal(hair.points.astype(np.float32), groom.points.astype(np.float32))
        np.testing.assert_array_equal(hair.thickness.astype(np.float32), groom.thickness.astype(np.float32))
        np.testing.assert_array_equal(hair.color.astype(np.float32), groom.color.astype(np.float32))
        held = {name: attribute for name, attribute in held.items() if spec.keeps_attribute(name, attribute)}
        assert sorted(hair.attributes) == sorted(held), fmt
        if fmt == "ply":  # roles have no place in PLY
            held = {name: HairAttribute(attribute.values, attribute.domain) for name, attribute in held.items()}
        for name, attribute in held.items():
            back = hair.attributes[name]
            assert (back.domain, back.values.dtype) == (attribute.domain, attribute.values.dtype), (fmt, name)
            np.testing.assert_array_equal(back.values, attribute.values)
            assert back.role == attribute.role, (fmt, name)
    assert list(held) == ["transparency"]  # .hair holds no other attribute


@pytest.mark.parametrize("fmt", ["npz", "usda", "usdc", "ply", "abc"])
def test_formats_with_attributes_keep_all_of_them(groom, fmt):
    with warnings.catch_warnings():
        warnings.simplefilter("error", HairIOWarning)
        back = read_hair_bytes_report(hair_to_bytes(groom, fmt), fmt, source=f"g.{fmt}").hair
    assert sorted(back.attributes) == sorted(groom.attributes)


@pytest.mark.parametrize("fmt, dropped", [("obj", "'transparency', 'uv', 'groom_group_id', 'root_uv'"),
                                          ("data", "thickness or color or attributes 'transparency'"),
                                          ("hair", "attributes 'uv', 'groom_group_id', 'root_uv'")])
def test_a_poorer_format_warns_once_naming_what_it_drops(groom, fmt, dropped):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        hair_to_bytes(groom, fmt)
    messages = [str(w.message) for w in caught if issubclass(w.category, HairIOWarning)]
    assert len(messages) == 1 and dropped in messages[0]
