"""The paper's Table 4 on this machine: multi-scale vs full solve on large grooms.

For each groom size, a fresh process (so peak memory is that size's alone) builds the
MakeHuman pair (average female -> heavy male) and a "long" groom, then measures:

* preprocess (anchors, guides, kNN sets) once;
* initial transfer and the multi-scale solve, median of ``--runs`` retargets;
* every baseline of ``solver.baselines`` once, in the same process (their time);
* peak memory: the process's resident high-water mark (reset through
  ``/proc/self/clear_refs``) during preprocessing and during the retargets, the latter plus
  each fine-level worker process at the largest one's peak (every process counted);
* the per-stage split (distance grid, coarse, fine with µs per particle per iteration; the segments
  through the body the solve cleared and the seconds that took; those left; how many iterations the
  fine level's strands took and how many the cap stopped) and a least-squares per-particle slope over
  the sizes.

The kernels are warmed first (``hairport warmup``: loaded from numba's on-disk cache), as in a
worker; the compile itself is measured by ``hairport warmup`` in a fresh cache.

The full (coupled, ``global``) solve runs in its own process with a wall-clock limit
(``--full-limit``, default 20 minutes); beyond it the table prints n/a. Where it finishes,
the mean distance between its result and the multi-scale one is printed, and both
results' penetration counts.

    python bench/table4.py [--sizes 1e5 1e6 3e6 1e7] [--runs 3] [--full-limit 1200] [--full-up-to 1e5]

Prints a table; not a test. Times are wall-clock seconds on this machine.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

#: particles per strand of the benchmark grooms (the paper's grooms have ~100)
PARTICLES_PER_STRAND = 100
#: below this size, strands get fewer particles so that there are still >= 1000 strands
SMALL_GROOM = 200_000
STYLE = "long"
SOURCE, TARGET = "average-female", "heavy-male"


def groom_shape(particles: int) -> tuple[int, int]:
    per_strand = 50 if particles < SMALL_GROOM else PARTICLES_PER_STRAND
    return max(1, round(particles / per_strand)), per_strand


def _status_bytes(field: str) -> int:
    """A memory figure of this process from /proc/self/status (``VmHWM``: peak, ``VmRSS``: now)."""
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith(f"{field}:"):
                return int(line.split()[1]) * 1024
    return 0


def _reset_peak() -> bool:
    try:
        with open("/proc/self/clear_refs", "w") as handle:
            handle.write("5")
        return True
    except OSError:
        return False


def measure_size(args) -> dict:
    """One size, in this process: preprocess, multi-scale retargets, baselines."""
    from hairport import solver
    from hairport.solver import kernels
    from hairport.solver import options as solver_options
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import PRESETS, build_character

    warm = kernels.warm_up()  # compiled kernels come from the on-disk cache, as in a warmed worker
    strands, per_strand = groom_shape(int(float(args.one)))
    source, target = build_character(PRESETS[SOURCE]), build_character(PRESETS[TARGET])
    hair = generate_groom(source, STYLE, strands, per_strand, seed=0)
    base_rss = _status_bytes("VmRSS")
    can_reset = _reset_peak()
    began = time.perf_counter()
    adaptable = solver.preprocess(source, hair, solver.PreprocessOptions(guides=args.guides))
    adaptable.coarse_model, adaptable.fine_source  # noqa: B018 - source-only, part of preprocessing
    preprocess = time.perf_counter() - began
    preprocess_peak = _status_bytes("VmHWM")

    options = solver.RetargetOptions(method="multiscale", workers=args.workers)
    runs, result = [], None
    retarget_base = _status_bytes("VmRSS")
    _reset_peak()
    for _ in range(args.runs):
        began = time.perf_counter()
        result = solver.retarget(adaptable, target, options)
        runs.append({"total": time.perf_counter() - began, **result.timings})
    peak = _status_bytes("VmHWM")
    children = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024
    np.save(args.save, result.hair.points)
    report = result.solve
    fine_particles = int(sum(hair.counts)) - int(sum(hair.counts[adaptable.multiscale.guides]))
    fine_iterations = max((f.iterations for f in report.fine), default=0)
    # particle-iterations the fine level worked on: each strand counts while it is open
    fine_work = sum(sum(f.open_groups) for f in report.fine) * per_strand

    baselines = {}
    for method in solver_options.BASELINE_METHODS:
        began = time.perf_counter()
        solver.retarget(adaptable, target, solver.RetargetOptions(method=f"{method}+pushout"))
        baselines[method] = time.perf_counter() - began

    def median(key: str) -> float:
        return statistics.median(run.get(key, 0.0) for run in runs)

    return {
        "strands": hair.n_strands,
        "particles": hair.n_particles,
        "guides": len(adaptable.multiscale.guides),
        "preprocess": preprocess,
        "initial_transfer": median("initial_transfer"),
        "distance_grid": median("distance_grid"),
        "solve": median("solve"),
        "coarse": median("coarse_solve"),
        "fine": median("fine_solve"),
        "metrics": median("metrics"),
        "total": median("initial_transfer") + median("solve"),
        "runs": len(runs),
        "peak_rss": peak if can_reset else None,
        "preprocess_peak_rss": preprocess_peak if can_reset else None,
        "base_rss": base_rss,
        "retarget_base_rss": retarget_base,
        "worker_peak_rss": children if report.workers > 1 else 0,
        "workers": report.workers,
        "penetrating": result.metrics["penetrating_particles"],
        "crossing": result.metrics["crossing_segments"]["count"],
        # the segments the solve found through the body and the seconds it took to clear them (both levels)
        "segments_cleared": sum(level.segments_crossing for level in [report.coarse, *report.fine] if level),
        "segment_seconds": sum(level.segment_seconds for level in [report.coarse, *report.fine] if level),
        "fine_spread": report.fine_iterations(),
        "coarse_iterations": report.coarse.iterations if report.coarse else 0,
        "fine_iterations": fine_iterations,
        "fine_particles": fine_particles,
        "fine_work": fine_work,
        "iterations": report.iterations,
        "kernels_compiled": warm.compiled,
        "baselines": baselines,
    }


def measure_full(args) -> dict:
    """The coupled solve of one size, in this process."""
    from hairport import solver
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import PRESETS, build_character

    strands, per_strand = groom_shape(int(float(args.full)))
    source, target = build_character(PRESETS[SOURCE]), build_character(PRESETS[TARGET])
    hair = generate_groom(source, STYLE, strands, per_strand, seed=0)
    adaptable = solver.preprocess(source, hair, solver.PreprocessOptions(guides=args.guides))
    began = time.perf_counter()
    result = solver.retarget(adaptable, target, solver.RetargetOptions(method="global"))
    seconds = time.perf_counter() - began - result.timings.get("metrics", 0.0)
    multiscale = np.load(args.compare)
    return {
        "full": seconds,
        "distance": float(np.linalg.norm(result.hair.points - multiscale, axis=1).mean()),
        "penetrating": result.metrics["penetrating_particles"],
    }


def _child(argv: list[str], timeout: float | None) -> dict | None:
    try:
        done = subprocess.run([sys.executable, __file__, *argv], capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return None
    if done.returncode != 0:
        print(done.stderr[-3000:], file=sys.stderr)
        return None
    return json.loads(done.stdout.strip().splitlines()[-1])


def _fmt(value, digits=1) -> str:
    return "n/a" if value is None else f"{value:.{digits}f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="+", default=["1e5", "1e6", "3e6"], help="particles per groom")
    parser.add_argument("--runs", type=int, default=3, help="multi-scale retargets per size (median)")
    parser.add_argument("--full-limit", type=float, default=1200.0, help="seconds allowed to the full solve")
    parser.add_argument("--full-up-to", type=float, default=1e5,
                        help="skip the full solve above this many particles (printed n/a)")
    parser.add_argument("--guides", type=int, default=300)
    parser.add_argument("--workers", type=int, default=None, help="fine-level processes (default: CPUs)")
    parser.add_argument("--one", help=argparse.SUPPRESS)
    parser.add_argument("--full", help=argparse.SUPPRESS)
    parser.add_argument("--save", help=argparse.SUPPRESS)
    parser.add_argument("--compare", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(measure_size(args)))
        return
    if args.full:
        print(json.dumps(measure_full(args)))
        return

    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        for size in args.sizes:
            saved = str(Path(scratch) / f"multiscale-{size}.npy")
            common = ["--guides", str(args.guides)] + (["--workers", str(args.workers)] if args.workers else [])
            row = _child(["--one", size, "--runs", str(args.runs), "--save", saved] + common, None)
            if row is None:
                print(f"size {size}: failed", file=sys.stderr)
                continue
            full = None
            if float(size) <= args.full_up_to:
                full = _child(["--full", size, "--compare", saved, "--guides", str(args.guides)], args.full_limit)
            row["full_solve"] = full
            rows.append(row)
            print(f"measured {size}: {json.dumps(row)}", file=sys.stderr, flush=True)

    print_tables(rows, args)


def _machine() -> str:
    model = "unknown CPU"
    try:
        with open("/proc/cpuinfo") as info:
            model = next((line.split(":", 1)[1].strip() for line in info if line.startswith("model name")), model)
    except OSError:
        pass
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    memory = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30
    return f"{model}, {cpus} CPUs, {memory:.0f} GiB, Python {sys.version.split()[0]}, {time.strftime('%Y-%m-%d')}"


def _slope(rows: list[dict], key: str) -> tuple[float, float]:
    """Least-squares ``seconds = a + b * particles`` over the sizes: (b in µs per particle, a in s)."""
    if len(rows) < 2:
        return float("nan"), float("nan")
    n = np.array([r["particles"] for r in rows], dtype=float)
    t = np.array([r[key] for r in rows], dtype=float)
    b, a = np.polyfit(n, t, 1)
    return 1e6 * b, a


def _peak(r: dict) -> float | None:
    """Every process of the retarget at its high-water mark: this one, plus each fine-level worker."""
    return None if r["peak_rss"] is None else r["peak_rss"] + r["worker_peak_rss"] * r["workers"]


def print_tables(rows: list[dict], args) -> None:
    print(f"{_machine()}")
    print(f"MakeHuman {SOURCE} -> {TARGET}, '{STYLE}' grooms, {args.guides} guides, median of {args.runs} retargets;"
          " seconds, (us/p) = microseconds per particle")
    header = (f"{'strands':>8} {'particles':>10} {'preproc':>8} {'(us/p)':>7} {'transfer':>8} {'(us/p)':>7} "
              f"{'solve':>7} {'(us/p)':>7} {'total':>7} {'(us/p)':>7} {'full':>7} {'speedup':>7} "
              f"{'peak MB':>8} {'B/p':>6}")
    print(header)
    print("-" * len(header))
    for r in rows:
        n = r["particles"]
        full = r["full_solve"]
        peak = _peak(r)
        full_time = full["full"] if full else None
        speedup = full_time / r["total"] if full_time else None
        print(f"{r['strands']:>8} {n:>10} {r['preprocess']:>8.1f} {1e6 * r['preprocess'] / n:>7.1f} "
              f"{r['initial_transfer']:>8.2f} {1e6 * r['initial_transfer'] / n:>7.1f} {r['solve']:>7.1f} "
              f"{1e6 * r['solve'] / n:>7.1f} {r['total']:>7.1f} {1e6 * r['total'] / n:>7.1f} {_fmt(full_time):>7} "
              f"{_fmt(speedup):>7} {_fmt(peak / 1e6 if peak else None, 0):>8} {_fmt(peak / n if peak else None, 0):>6}")
    print()
    print("solve by stage (s): target distance grid / coarse level (guides, iterations) / fine level (iterations,"
          " us per particle per iteration: by iterations run, and by open strands' particles)")
    for r in rows:
        per_iteration = 1e6 * r["fine"] / max(1, r["fine_particles"] * r["fine_iterations"])
        per_work = 1e6 * r["fine"] / max(1, r["fine_work"])
        print(f"  {r['particles']:>10}: {r['distance_grid']:.2f} / {r['coarse']:.2f} ({r['coarse_iterations']} it) / "
              f"{r['fine']:.2f} ({r['fine_iterations']} it; {per_iteration:.3f} / {per_work:.3f} us/p/it); "
              f"metrics {r['metrics']:.2f}; {r['penetrating']} penetrating, {r.get('crossing', 0)} crossing segments "
              f"({r.get('segments_cleared', 0)} cleared in {r.get('segment_seconds', 0.0):.2f} s)")
        spread = r.get("fine_spread")
        if spread:
            print(f"  {'':>10}  fine-level strands by iterations: p50 {spread['p50']}, p90 {spread['p90']}, "
                  f"p99 {spread['p99']}, max {spread['max']}; {spread['capped']} of {spread['strands']} stopped by the cap")
    print()
    print("memory (MB): process before preprocessing / preprocessing peak / before the retarget / retarget peak"
          " (all processes); fine-level processes")
    for r in rows:
        def mb(value):
            return _fmt(value / 1e6 if value else None, 0)

        print(f"  {r['particles']:>10}: {mb(r['base_rss'])} / {mb(r['preprocess_peak_rss'])} / "
              f"{mb(r['retarget_base_rss'])} / {mb(_peak(r))}; {r['workers']}")
    for r in rows:
        full = r["full_solve"]
        if full:
            print(f"  full solve at {r['particles']}: {full['penetrating']} penetrating, mean distance to multi-scale "
                  f"{1e3 * full['distance']:.2f} mm")
    print()
    names = sorted(rows[0]["baselines"]) if rows else []
    print("baselines (+pushout), seconds in the same process, and ours (total) against the cheapest: "
          + ", ".join(names))
    for r in rows:
        cheapest = min(r["baselines"].values())
        print(f"  {r['particles']:>10}: " + "  ".join(f"{r['baselines'][m]:.2f}" for m in names)
              + f"; ours {r['total']:.2f} = {r['total'] / cheapest:.1f}x the cheapest")
    print()
    for key, label in (("total", "total (transfer + solve)"), ("preprocess", "preprocess"), ("fine", "fine level")):
        slope, intercept = _slope(rows, key)
        print(f"linear fit over the sizes, {label}: {slope:.2f} us per particle + {intercept:.2f} s")


if __name__ == "__main__":
    main()
