"""Byte budget, per-strand limit and memory estimate of the hair readers: refused before the work."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest

from hairport.solver import InputError
from hairport.solver.budget import BYTES_PER_PARTICLE, estimate_bytes
from hairport.solver.io.hair import ReadLimits, read_hair_bytes


def _member(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.lib.format.write_array(buffer, array)
    return buffer.getvalue()


def bomb(points: int, claimed: int | None = None) -> bytes:
    """A hairport .npz of one strand of ``points`` zeros, deflated; its points member's declared
    size is rewritten to ``claimed`` bytes when given (a lying zip header)."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, array in (("format", np.array("hairport-hair")), ("version", np.array(1)),
                            ("units", np.array("m")), ("offsets", np.array([0, points]))):
            archive.writestr(f"{name}.npy", _member(array))
        archive.writestr("points.npy", _member(np.zeros((points, 3))))
    data = buffer.getvalue()
    if claimed is not None:  # patch the central directory's uncompressed size of points.npy
        at = data.rindex(b"points.npy") - 46 + 24
        data = data[:at] + np.uint32(claimed).tobytes() + data[at + 4:]
    return data


def test_a_bomb_is_refused_from_its_declared_unpacked_size():
    data = bomb(1_000_000)  # 24 MB of zeros in ~25 KB
    assert len(data) < 100_000
    with pytest.raises(InputError) as error:
        read_hair_bytes(data, "npz", limits=ReadLimits(max_bytes=1_000_000))
    assert error.value.code == "too_large"
    assert "unpacks to 24,000," in error.value.problem


def test_a_zip_header_that_understates_the_size_does_not_unpack_more():
    with pytest.raises(InputError) as error:
        read_hair_bytes(bomb(1_000_000, claimed=1_000), "npz", limits=ReadLimits(max_bytes=1_000_000))
    # zipfile stops the member at its declared 1,000 bytes: the CRC of what was read fails
    assert error.value.code == "bad_header"
    assert "Bad CRC-32" in error.value.problem


def test_one_strand_of_millions_of_points_is_refused():
    with pytest.raises(InputError) as error:
        read_hair_bytes(bomb(2_000_000), "npz")
    assert error.value.code == "too_large"
    assert "strand 0 has 2,000,000 points, above the limit of 10,000 per strand" in error.value.problem


def test_the_memory_estimate_refuses_what_cannot_fit():
    points = np.cumsum(np.ones((5_000, 3)), axis=0) * 1e-3
    data = io.BytesIO()
    np.savez(data, format=np.array("hairport-hair"), version=np.array(1), units=np.array("m"), points=points,
             offsets=np.arange(0, 5_001, 50))
    budget = estimate_bytes(5_000) - 1
    with pytest.raises(InputError) as error:
        read_hair_bytes(data.getvalue(), "npz", limits=ReadLimits(memory_budget_bytes=budget))
    assert error.value.code == "over_memory_budget"
    hair = read_hair_bytes(data.getvalue(), "npz", limits=ReadLimits(memory_budget_bytes=budget + 1))
    assert hair.n_particles == 5_000
    assert estimate_bytes(10**6) == 10**6 * BYTES_PER_PARTICLE
    assert estimate_bytes(10**6, k=64) > estimate_bytes(10**6)
