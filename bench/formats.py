"""Benchmark of the hair formats: write and read time and file size per format, with attributes.

For a groom of S strands x 32 points carrying thickness, colour and four attributes (a per-point
UV pair, a per-point float, a per-strand group id and guide flag), prints per format the median
over runs of the write and read times (hair_to_bytes / read_hair_bytes, i.e. without the disk),
bytes per particle, and which attributes survived. The ratio column is the time against
``.npz`` (hairport's own archive) measured in the same run. USD and Alembic parse in a child
process (the sandbox): their read time includes starting it.

    python bench/formats.py [--runs 3] [--strands 3000 30000]
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time
import warnings
from datetime import date

import numpy as np

from hairport.solver.io.hair import FORMATS, HairIOWarning, hair_to_bytes, read_hair_bytes
from hairport.solver.model.hair import Hair, HairAttribute

POINTS_PER_STRAND = 32


def groom(n_strands: int) -> Hair:
    rng = np.random.default_rng(0)
    n = n_strands * POINTS_PER_STRAND
    points = np.cumsum(rng.normal(0, 0.003, (n, 3)), axis=0)
    offsets = np.arange(0, n + 1, POINTS_PER_STRAND)
    attributes = {
        "uv": HairAttribute(rng.random((n, 2)).astype(np.float32), "vertex", "texcoord"),
        "density": HairAttribute(rng.random(n).astype(np.float32), "vertex"),
        "groom_group_id": HairAttribute(rng.integers(0, 8, n_strands).astype(np.int32), "strand"),
        "groom_guide": HairAttribute((np.arange(n_strands) % 50 == 0).astype(np.int16), "strand"),
    }
    return Hair(points, offsets, rng.random(n) * 1e-4, rng.random((n, 3)), attributes)


def median_seconds(run, runs: int) -> float:
    times = []
    for _ in range(runs):
        began = time.perf_counter()
        run()
        times.append(time.perf_counter() - began)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--strands", type=int, nargs="+", default=[3_000, 30_000])
    args = parser.parse_args()
    print(f"# {platform.node()} ({platform.processor() or platform.machine()}), {date.today()}, median of {args.runs}")
    warnings.simplefilter("ignore", HairIOWarning)
    for n_strands in args.strands:
        hair = groom(n_strands)
        print(f"\n{n_strands:,} strands, {hair.n_particles:,} particles, 4 attributes")
        print("| format | write s | read s | read / npz | bytes per particle | attributes kept |")
        print("|---|---|---|---|---|---|")
        rows, npz_read = [], None
        for name in FORMATS:
            if name == "usd":  # the same crate writer as usdc
                continue
            data = hair_to_bytes(hair, name)
            write = median_seconds(lambda name=name: hair_to_bytes(hair, name), args.runs)
            read = median_seconds(lambda name=name, data=data: read_hair_bytes(data, name), args.runs)
            kept = len(read_hair_bytes(data, name).attributes)
            npz_read = read if name == "npz" else npz_read
            rows.append((name, write, read, len(data) / hair.n_particles, kept))
        for name, write, read, size, kept in rows:
            print(f"| {name} | {write:.3f} | {read:.3f} | {read / npz_read:.1f} | {size:.0f} | {kept} of 4 |")


if __name__ == "__main__":
    main()
