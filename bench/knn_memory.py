"""Preprocessing time and peak memory per particle: one long strand vs an ordinary groom.

The inter-strand kNN (Eq. 8-9) once grew quadratically for a particle whose nearest
particles all lie on its own strand (one 10,000-point strand took 4.3 GB). This script
preprocesses, on the MakeHuman average female, a groom of ONE strand of ``--particles``
points and an ordinary groom of the same size (``--particles / 50`` strands of 50 points),
and prints per particle the preprocessing time and the peak resident memory above the
process's footprint before preprocessing (VmHWM after a reset through
``/proc/self/clear_refs``, minus VmRSS before). Each run is a fresh process; the table holds
the median of ``--runs``. Preprocessing here is what ``hairport preprocess`` computes:
anchors, guides, both kNN sets, and the source-only arrays of the coarse and fine levels.

    python bench/knn_memory.py [--particles 1e5] [--runs 3] [--style curly]

Prints a table; not a test. Target: the single strand within 2x the ordinary groom's time
and memory per particle.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

from table4 import _reset_peak, _status_bytes  # bench/table4.py, beside this script

#: points per strand of the ordinary groom (the benchmark grooms of bench/table4.py at 10^5)
ORDINARY_PER_STRAND = 50
SOURCE = "average-female"
CASES = ("single strand", "ordinary groom")


def shape(case: str, particles: int) -> tuple[int, int]:
    """(strands, points per strand) of a case."""
    if case == CASES[0]:
        return 1, particles
    return max(1, particles // ORDINARY_PER_STRAND), ORDINARY_PER_STRAND


def measure(case: str, particles: int, style: str) -> dict:
    """One preprocessing of one case, in this process."""
    from hairport import solver
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import PRESETS, build_character

    strands, per_strand = shape(case, particles)
    source = build_character(PRESETS[SOURCE])
    hair = generate_groom(source, style, strands, per_strand, seed=0)
    base = _status_bytes("VmRSS")
    can_reset = _reset_peak()
    began = time.perf_counter()
    adaptable = solver.preprocess(source, hair)
    adaptable.coarse_model, adaptable.fine_source  # noqa: B018 - source-only, part of preprocessing
    seconds = time.perf_counter() - began
    peak = _status_bytes("VmHWM") - base if can_reset else None
    return {"strands": hair.n_strands, "particles": hair.n_particles, "seconds": seconds, "peak": peak}


def _child(case: str, args) -> dict | None:
    argv = [sys.executable, __file__, "--one", case, "--particles", str(args.particles), "--style", args.style]
    done = subprocess.run(argv, capture_output=True, text=True)
    if done.returncode != 0:
        print(f"{case}: exit {done.returncode}\n{done.stderr[-3000:]}", file=sys.stderr)
        return None
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--particles", type=float, default=1e5, help="particles of each groom")
    parser.add_argument("--runs", type=int, default=3, help="fresh processes per case (median)")
    parser.add_argument("--style", default="curly", help="procedural groom style (solver.synthetic.groom)")
    parser.add_argument("--one", help=argparse.SUPPRESS)
    args = parser.parse_args()
    args.particles = int(args.particles)
    if args.one:
        print(json.dumps(measure(args.one, args.particles, args.style)))
        return

    rows = {}
    for case in CASES:
        runs = [run for run in (_child(case, args) for _ in range(args.runs)) if run is not None]
        if runs:
            peaks = [run["peak"] for run in runs if run["peak"] is not None]
            rows[case] = {**runs[0], "seconds": statistics.median(run["seconds"] for run in runs),
                          "peak": statistics.median(peaks) if peaks else None, "runs": len(runs)}
    print(f"MakeHuman {SOURCE}, '{args.style}' grooms, {os.cpu_count()} CPUs, median of {args.runs} fresh "
          "processes; preprocess = anchors, guides, kNN sets, coarse/fine source arrays; peak = resident "
          "high-water mark above the process before preprocessing")
    header = (f"{'case':<15} {'strands':>8} {'particles':>10} {'preproc s':>10} {'us/p':>7} "
              f"{'peak MB':>8} {'B/p':>7} {'time/p vs ordinary':>19} {'B/p vs ordinary':>16}")
    print(header)
    print("-" * len(header))
    ordinary = rows.get(CASES[1])
    for case, row in rows.items():
        n = row["particles"]
        per_us = 1e6 * row["seconds"] / n
        per_b = None if row["peak"] is None else row["peak"] / n
        time_ratio = peak_ratio = "n/a"
        if ordinary is not None:
            time_ratio = f"{per_us / (1e6 * ordinary['seconds'] / ordinary['particles']):.2f}x"
            if per_b is not None and ordinary["peak"]:
                peak_ratio = f"{per_b / (ordinary['peak'] / ordinary['particles']):.2f}x"
        peak_mb = "n/a" if row["peak"] is None else f"{row['peak'] / 1e6:.0f}"
        per_b_text = "n/a" if per_b is None else f"{per_b:.0f}"
        print(f"{case:<15} {row['strands']:>8,} {n:>10,} {row['seconds']:>10.2f} {per_us:>7.1f} "
              f"{peak_mb:>8} {per_b_text:>7} {time_ratio:>19} {peak_ratio:>16}")
    for case in CASES:
        if case not in rows:
            print(f"{case:<15} failed (see stderr)")


if __name__ == "__main__":
    main()
