"""Preprocessing and the retarget's stages outside the shape solver: time and peak memory per particle.

For each groom size, a fresh process (so peak memory is that size's alone) builds the
MakeHuman pair (average female -> heavy male) and a "long" groom (the grooms of
``bench/table4.py``), then runs, stage by stage, what a user waits for outside the shape
solver:

* preprocessing: ``solver.preprocess`` (its stages as it reports them through its progress
  callback), then the source-only arrays every retarget builds from it (the coarse level's
  operators, the fine level's source arrays, Eq. 5's strand Laplacian);
* the retarget without the solve, as ``solver.retarget`` runs it: prepare the target,
  initial transfer (Eq. 3-6; the shape carry after it is its own row, ``shape_carry``), the
  distance grid of the multi-scale solve, the penetration check and the metrics (of the
  initial transfer, standing in for a result; the metrics' kNN over all strands is its own
  row, ``metrics_knn``).

With ``--solve`` the retarget is ``solver.retarget`` itself, shape solve included (its
stages as reported through its progress callback; the distance grid is then inside
``solve``), and the fine level's worker processes are counted in the peak.

Per stage: wall-clock seconds (median of ``--runs`` processes), microseconds per particle,
and the process's resident high-water mark during the stage (``VmHWM`` after a reset through
``/proc/self/clear_refs``, the median over the runs). ``peak`` is the largest of these (plus,
with ``--solve``, the fine level's workers at the largest one's peak each), ``B/p`` that
over the particle count, ``B/p above base`` the same above the process before the groom was
made (interpreter, libraries, the two characters, the compiled kernels: each process first
loads them from numba's on-disk cache, as a worker does at start, ``kernels warm-up``).

``--baseline-python`` runs every size also under another interpreter (e.g. a venv with an
older checkout installed) in the same invocation, alternating, and prints both tables and
the ratios after / before.

    python bench/preprocess.py [--sizes 1e5 1e6 3e6] [--runs 1] [--solve] [--baseline-python PATH]

Prints tables; not a test.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from contextlib import contextmanager

from table4 import SOURCE, STYLE, TARGET, _reset_peak, _status_bytes, groom_shape  # bench/table4.py, beside this script

GUIDES = 300


class StageMeter:
    """Seconds and resident high-water mark of consecutive stages.

    Works as a progress callback (a new stage name closes the previous stage) and as a
    context manager per stage (:meth:`stage`).
    """

    def __init__(self) -> None:
        self.stages: dict[str, dict] = {}
        self._open: str | None = None
        self._began = 0.0

    def _close(self) -> None:
        if self._open is not None:
            seconds = time.perf_counter() - self._began
            entry = self.stages.setdefault(self._open, {"seconds": 0.0, "peak": 0})
            entry["seconds"] += seconds
            entry["peak"] = max(entry["peak"], _status_bytes("VmHWM"))
            self._open = None

    def _start(self, name: str) -> None:
        self._close()
        _reset_peak()
        self._open = name
        self._began = time.perf_counter()

    def __call__(self, stage: str, fraction: float, message: str) -> None:
        if stage != self._open:
            self._start(stage)

    def finish(self) -> None:
        self._close()

    @contextmanager
    def stage(self, name: str):
        self._start(name)
        yield
        self._close()


class _PreprocessStages:
    """Progress of ``solver.preprocess``: its stages as it names them, until it reports ``preprocess`` (done)."""

    def __init__(self, meter: StageMeter) -> None:
        self.meter = meter

    def __call__(self, stage: str, fraction: float, message: str) -> None:
        if stage == "preprocess":
            self.meter.finish()
        else:
            self.meter(stage, fraction, message)


def measure_size(size: str, solve: bool, workers: int | None) -> dict:
    """One size, in this process."""
    import numpy as np

    from hairport import solver
    from hairport.solver.kernels import warm_up
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import PRESETS, build_character

    strands, per_strand = groom_shape(int(float(size)))
    source, target = build_character(PRESETS[SOURCE]), build_character(PRESETS[TARGET])
    began = time.perf_counter()
    warm_up()  # the compiled kernels, from numba's on-disk cache (compiled there if missing), as a worker at start
    warm_seconds = time.perf_counter() - began
    base = _status_bytes("VmRSS")
    hair = generate_groom(source, STYLE, strands, per_strand, seed=0)
    groom = _status_bytes("VmRSS")
    meter = StageMeter()
    began = time.perf_counter()
    adaptable = solver.preprocess(source, hair, solver.PreprocessOptions(guides=GUIDES),
                                  progress=_PreprocessStages(meter))
    meter.finish()
    with meter.stage("coarse_model"):
        adaptable.coarse_model  # noqa: B018 - lazy, source-only
    with meter.stage("fine_source"):
        adaptable.fine_source  # noqa: B018
    with meter.stage("strand_laplacian"):
        adaptable.strand_laplacian  # noqa: B018
    preprocess = time.perf_counter() - began
    worker_peak, used_workers = 0, 1
    if solve:
        options = solver.RetargetOptions(method="multiscale", workers=workers)
        result = solver.retarget(adaptable, target, options, progress=meter)
        meter.finish()
        used_workers = result.solve.workers
        if used_workers > 1:
            worker_peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024
        penetrating = result.metrics["penetrating_particles"]
    else:
        penetrating = _retarget_without_solve(adaptable, target, meter, np)
    stages = meter.stages
    process_peak = max(entry["peak"] for entry in stages.values())
    return {
        "particles": hair.n_particles,
        "strands": hair.n_strands,
        "preprocess": preprocess,
        "stages": stages,
        "base": base,
        "warm_up": warm_seconds,
        "groom": groom,
        "process_peak": process_peak,
        "peak": process_peak + worker_peak * used_workers,
        "workers": used_workers,
        "penetrating": penetrating,
    }


def _retarget_without_solve(adaptable, target, meter: StageMeter, np) -> int:
    """``solver.retarget``'s stages outside the shape solve, on the initial transfer."""
    from hairport.solver import metrics as solver_metrics
    from hairport.solver.body.target import prepare_target
    from hairport.solver.mesh.collision import collision_query
    from hairport.solver.mesh.distance_grid import DistanceGrid
    from hairport.solver.mesh.penetration import resolve_penetration
    from hairport.solver.mesh.query import MeshQuery
    from hairport.solver.options import RetargetOptions
    from hairport.solver.pipeline import GRID_REGION_MARGIN, initial_transfer
    from hairport.solver.transfer.anchors import root_targets

    options = RetargetOptions()
    hair = adaptable.hair
    with meter.stage("prepare"):
        target = prepare_target(adaptable, target)
        target_query = MeshQuery(target.vertices, target.faces)
        body = collision_query(target.vertices, target.faces, target.name)
    with meter.stage("initial_transfer"):
        initial, _ = initial_transfer(adaptable, target, options.eps_s, target_query)
    carry = getattr(options, "carry", 0.0)  # an older checkout has none
    if carry:
        from hairport.solver.transfer.carry import carry_shapes

        with meter.stage("shape_carry"):
            initial = carry_shapes(initial, hair.points, hair.offsets, hair.is_root, carry)
    roots = root_targets(target, adaptable.anchors.face[hair.roots], adaptable.anchors.barycentric[hair.roots])
    with meter.stage("distance_grid"):
        reach = (initial.min(axis=0) - GRID_REGION_MARGIN, initial.max(axis=0) + GRID_REGION_MARGIN)
        DistanceGrid.build(target_query, region=reach)
    with meter.stage("penetration_check"):
        points, _ = resolve_penetration(initial, hair.is_root, body, options.eps_c, target.name)
    with meter.stage("metrics_knn"):
        # lazy: the metrics' kNN over all strands (Eq. 8-9; the full ShapeModel before it took its place)
        adaptable.neighbours if hasattr(solver_metrics, "interstrand_residual") else adaptable.shape_model  # noqa: B018
    with meter.stage("metrics"):
        if hasattr(solver_metrics, "interstrand_residual"):
            metrics = solver_metrics.hairstyle_metrics(points, hair, initial, roots, adaptable.neighbours, target_query,
                                                       options.eps_c, body=body)
        else:  # the signature before it (a baseline interpreter with an older checkout)
            metrics = solver_metrics.hairstyle_metrics(points, hair.points, initial, hair.is_root, roots,
                                                       adaptable.shape_model, target_query, options.eps_c, body=body)
    return metrics["penetrating_particles"]


def _child(python: str, size: str, args) -> dict | None:
    argv = [python, __file__, "--one", size] + (["--solve"] if args.solve else [])
    argv += ["--workers", str(args.workers)] if args.workers else []
    done = subprocess.run(argv, capture_output=True, text=True)
    if done.returncode != 0:
        print(done.stderr[-3000:], file=sys.stderr)
        return None
    return json.loads(done.stdout.strip().splitlines()[-1])


def _median_runs(runs: list[dict]) -> dict:
    """Per-stage medians of several runs of one size."""
    first = runs[0]
    stages = {
        name: {key: statistics.median(run["stages"][name][key] for run in runs if name in run["stages"])
               for key in ("seconds", "peak")}
        for name in first["stages"]
    }
    out = {key: first[key] for key in ("particles", "strands", "workers", "penetrating")}
    for key in ("preprocess", "base", "warm_up", "groom", "process_peak", "peak"):
        out[key] = statistics.median(run[key] for run in runs)
    out["stages"] = stages
    return out


def _print_table(label: str, rows: list[dict]) -> None:
    print(f"{label}")
    header = f"{'stage':>18}" + "".join(f" {'s':>7} {'us/p':>6} {'MB':>6} {'B/p':>5}" for _ in rows)
    sizes = f"{'particles':>18}" + "".join(f" {row['particles']:>26,}" for row in rows)
    print(sizes)
    print(header)
    print("-" * len(header))
    names = list(dict.fromkeys(name for row in rows for name in row["stages"]))
    for name in names:
        line = f"{name:>18}"
        for row in rows:
            entry = row["stages"].get(name)
            if entry is None:
                line += f" {'':>26}"
                continue
            n = row["particles"]
            line += (f" {entry['seconds']:>7.2f} {1e6 * entry['seconds'] / n:>6.2f} {entry['peak'] / 1e6:>6.0f}"
                     f" {entry['peak'] / n:>5.0f}")
        print(line)
    print("-" * len(header))
    line = f"{'preprocess':>18}"
    for row in rows:
        n = row["particles"]
        line += f" {row['preprocess']:>7.2f} {1e6 * row['preprocess'] / n:>6.2f} {'':>6} {'':>5}"
    print(line)
    line = f"{'peak':>18}"
    for row in rows:
        line += f" {'':>7} {'':>6} {row['peak'] / 1e6:>6.0f} {row['peak'] / row['particles']:>5.0f}"
    print(line)
    line = f"{'kernels warm-up':>18}"
    for row in rows:
        line += f" {row['warm_up']:>7.2f} {'':>6} {'':>6} {'':>5}"
    print(line)
    line = f"{'B/p above base':>18}"
    for row in rows:
        line += f" {'':>7} {'':>6} {row['base'] / 1e6:>6.0f} {(row['peak'] - row['base']) / row['particles']:>5.0f}"
    print(line)
    print()


def _print_ratios(after: list[dict], before: list[dict]) -> None:
    print("ratios after / before (seconds, peak MB)")
    for a, b in zip(after, before):
        parts = [f"preprocess {a['preprocess'] / b['preprocess']:.2f}", f"peak {a['peak'] / b['peak']:.2f}"]
        for name, entry in a["stages"].items():
            old = b["stages"].get(name)
            if old and old["seconds"] > 0:
                parts.append(f"{name} {entry['seconds'] / old['seconds']:.2f}")
        print(f"  {a['particles']:>10,}: " + ", ".join(parts))
    print()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="+", default=["1e5", "1e6", "3e6"], help="particles per groom")
    parser.add_argument("--runs", type=int, default=1, help="fresh processes per size (medians)")
    parser.add_argument("--solve", action="store_true", help="retarget with the shape solve (solver.retarget)")
    parser.add_argument("--workers", type=int, default=None, help="fine-level processes with --solve")
    parser.add_argument("--baseline-python", help="also run every size under this interpreter (before)")
    parser.add_argument("--one", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one:
        print(json.dumps(measure_size(args.one, args.solve, args.workers)))
        return

    pythons = {"after": sys.executable}
    if args.baseline_python:
        pythons = {"before": args.baseline_python, **pythons}
    rows: dict[str, list[dict]] = {label: [] for label in pythons}
    for size in args.sizes:
        runs: dict[str, list[dict]] = {label: [] for label in pythons}
        for _ in range(args.runs):
            for label, python in pythons.items():  # alternating, so both see the same machine load
                row = _child(python, size, args)
                if row is not None:
                    runs[label].append(row)
                    print(f"measured {label} {size}: preprocess {row['preprocess']:.2f} s, "
                          f"peak {row['peak'] / 1e6:.0f} MB", file=sys.stderr, flush=True)
        for label in pythons:
            if runs[label]:
                rows[label].append(_median_runs(runs[label]))

    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    print(f"MakeHuman {SOURCE} -> {TARGET}, '{STYLE}' grooms, {GUIDES} guides, {cpus} CPUs, median of "
          f"{args.runs} process(es) per size; s = seconds, us/p = microseconds per particle, MB = resident "
          f"high-water mark during the stage, B/p = that per particle")
    print()
    for label, table in rows.items():
        _print_table(f"{label} ({pythons[label]})" if len(pythons) > 1 else pythons[label], table)
    if len(pythons) > 1 and rows["before"] and rows["after"]:
        _print_ratios(rows["after"], rows["before"])


if __name__ == "__main__":
    main()
