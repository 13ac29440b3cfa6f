"""USC-HairSalon ``.data`` hair files.

Layout: little-endian ``int32`` strand count, then per strand ``int32 n`` and ``n * 3``
``float32`` coordinates. Written as float32. The format has no thickness or color.
USC-HairSalon files mark scalp positions without hair by strands of a single point; the
reader keeps them in its :class:`~.common.Strands` and the shared read step drops them.
"""

from __future__ import annotations

import struct
from typing import BinaryIO

import numpy as np

from hairport.solver.io.hair.common import (
    INT32_MAX,
    HairFormat,
    ReadContext,
    Strands,
    WriteOptions,
    check_fits,
    no_trailing,
    require_bytes,
    to_float32,
)
from hairport.solver.model.hair import Hair

DATA_HEADER_BYTES = 4  # int32 strand count
DATA_COUNT_BYTES = 4  # int32 points of one strand
DATA_POINT_BYTES = 12  # float32 x, y, z
_INT32 = struct.Struct("<i")


def read_data(buf: bytes | memoryview, ctx: ReadContext) -> Strands:
    """Parse ``int32 S``, then per strand ``int32 n`` and ``n`` float32 triples.

    Returns
    -------
    strands : Strands
        ``points (N, 3) float32``, ``counts (S,) int64``.
    """
    size = len(buf)
    require_bytes(ctx, DATA_HEADER_BYTES, size, "the strand count")
    n_strands = _INT32.unpack_from(buf, 0)[0]
    if n_strands < 0:
        raise ctx.error(f"the header declares a negative strand count ({n_strands})", "bad_header")
    require_bytes(
        ctx,
        DATA_HEADER_BYTES + DATA_COUNT_BYTES * n_strands,
        size,
        f"a header of {n_strands:,} strands",
    )
    ctx.check_limit(n_strands, "strands")
    counts = strand_counts(buf, n_strands, ctx)
    ctx.check_limit(int(counts.sum()), "particles")
    words = np.frombuffer(buf, dtype="<f4", offset=DATA_HEADER_BYTES)
    count_words = np.zeros(len(counts) + 1, dtype=np.int64)
    np.cumsum(counts * 3 + 1, out=count_words[1:])
    is_point = np.ones(len(words), dtype=bool)
    is_point[count_words[:-1]] = False
    points = words[is_point].reshape(-1, 3)
    return Strands(points, counts)


def strand_counts(buf: bytes | memoryview, n_strands: int, ctx: ReadContext) -> np.ndarray:
    """Points per strand, walking the interleaved counts; checks the file ends with the data.

    Each strand's position depends on all earlier counts, so the walk is sequential. When
    all strands have the first strand's length (resampled grooms) one vectorized check
    replaces it; otherwise a loop does integer arithmetic only (about 0.3 µs a strand).

    Returns
    -------
    counts : (S,) int64
    """
    size = len(buf)
    if n_strands == 0:
        no_trailing(ctx, DATA_HEADER_BYTES, size)
        return np.zeros(0, dtype=np.int64)
    first = _INT32.unpack_from(buf, DATA_HEADER_BYTES)[0]
    stride = DATA_COUNT_BYTES + DATA_POINT_BYTES * first
    if first >= 0 and DATA_HEADER_BYTES + n_strands * stride == size:
        table = np.frombuffer(buf, dtype="<i4", offset=DATA_HEADER_BYTES).reshape(n_strands, -1)
        if (table[:, 0] == first).all():
            return np.full(n_strands, first, dtype=np.int64)
    unpack = _INT32.unpack_from
    counts = [0] * n_strands
    pos = DATA_HEADER_BYTES
    for s in range(n_strands):
        if pos + DATA_COUNT_BYTES > size:
            raise ctx.error(
                f"the file ends at byte {size:,}, inside the point count of strand {s:,} "
                f"of {n_strands:,}",
                "truncated",
            )
        n = unpack(buf, pos)[0]
        if n < 0:
            raise ctx.error(f"strand {s:,} declares a negative point count ({n})", "bad_header")
        counts[s] = n
        pos += DATA_COUNT_BYTES + DATA_POINT_BYTES * n
        if pos > size:
            raise ctx.error(
                f"strand {s:,} of {n_strands:,} declares {n:,} points, which run past the end "
                f"of the file (byte {size:,})",
                "truncated",
            )
    no_trailing(ctx, pos, size)
    return np.array(counts, dtype=np.int64)


def write_data(f: BinaryIO, hair: Hair, options: WriteOptions) -> None:
    """Write the strand count, then every strand's point count and float32 points."""
    check_fits(hair, INT32_MAX, INT32_MAX, "data")
    counts = hair.counts
    words = np.empty(1 + hair.n_strands + 3 * hair.n_particles, dtype="<i4")
    words[0] = hair.n_strands
    count_at = 1 + np.arange(hair.n_strands, dtype=np.int64) + 3 * hair.offsets[:-1]
    is_point = np.ones(len(words), dtype=bool)
    is_point[0] = False
    is_point[count_at] = False
    words[count_at] = counts
    words.view("<f4")[is_point] = to_float32(hair.points / options.scale, "coordinate").ravel()
    f.write(memoryview(words).cast("B"))


FORMAT = HairFormat("data", read_data, write_data, keeps_thickness=False, keeps_color=False)
