"""Benchmark of the exact signed distance near the body: libigl's AABB against the compiled BVH.

Prints, for the MakeHuman "heavy-male" body (26,756 faces) and hair-like points (the
procedural ``long`` groom, strands of 100 particles, kept where ``|d| < 2 cm``: the particles
the solver's broad phase sends to the exact query, most of them a few mm from the skin), the
median over runs of :meth:`MeshQuery.signed_distance` in microseconds per point:

* ``igl``: libigl's AABB, Z-curve ordered, the numpy sign steps (the previous default; the
  baseline of the ratio column);
* ``bvh``: the compiled tree, one fused pass per point;
* ``bvh hinted``: the same, seeded with each point's face at the previous iterate;
* ``cells, empty``: through a new cell cache (its cells filled during the call);
* ``cells, filled``: through a cache filled at the previous iterate (the solver's steady state).

A query is of an iterate: the groom's particles moved by a random step (0.3 mm per axis);
the previous iterate is the groom itself. Every method is checked against libigl (distance,
closest point, sign; faces may differ only on ties). Methods run round-robin within each
run, so load from other processes hits them alike; the ratio is igl's median over the
method's. The CPU column is process time over all threads.

With ``--compile``, two fresh processes over an empty numba cache time the warm-up of the
kernel module (wall, and the process's CPU time with its imports): the first compiles and
saves, the second loads the cache.

With ``--retarget N``, multi-scale retargets (MakeHuman average female -> heavy male, a
``long`` groom of about N particles, one process: ``workers=1``) run round-robin with the
target's face search on libigl and on the compiled BVH (whose :class:`BodyDistance` keeps a
cell cache); printed: the retarget's and the solve's seconds, the seconds inside
``BodyDistance`` and its calls and particles, and how far the two results are apart.

    python bench/closest_point.py [--runs 3] [--groom 1000x100 10000x100] [--compile] [--retarget 1e5]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

from hairport.solver import jit, kernels
from hairport.solver.mesh import backends
from hairport.solver.mesh.query import MeshQuery

#: particles farther than this (m) are skipped by the solver's broad phase (CONTACT_BAND)
BAND = 0.02
#: per-axis standard deviation (m) of the step from one iterate to the next
STEP = 3e-4

WARM_MODULES = ("hairport.solver.mesh.closest_kernels",)


def forced(vertices, faces, backend):
    query = MeshQuery(vertices, faces)
    query._prepare()
    query._closest = backends._closest_face_index(query.vertices, query.faces, [backend])
    return query


def hair_points(character, strands, per_strand, rng):
    """(previous iterate, iterate) of the groom's particles within BAND of the body."""
    from hairport.solver.synthetic.groom import generate_groom

    points = generate_groom(character, "long", strands, per_strand, seed=0).points
    query = MeshQuery(character.vertices, character.faces)
    near = np.abs(query.signed_distance(points).distance) < BAND
    previous = np.ascontiguousarray(points[near])
    return previous, previous + rng.normal(scale=STEP, size=previous.shape)


def check(reference, result, label):
    """Same distances, closest points and signs as libigl's; faces may differ on ties only."""
    assert np.abs(result.distance - reference.distance).max() <= 1e-12, label
    assert np.abs(result.closest - reference.closest).max() <= 1e-12, label
    np.testing.assert_array_equal(result.distance < 0, reference.distance < 0, err_msg=label)
    return int(np.count_nonzero(result.faces != reference.faces))


def compile_times():
    """(wall, CPU) seconds of the warm-up of WARM_MODULES in a first fresh process over an
    empty numba cache (compiles) and in a second (loads the cache)."""
    code = (
        "import importlib, time; began = time.perf_counter()\n"
        f"for name in {WARM_MODULES!r}: importlib.import_module(name)._warm()\n"
        "print(time.perf_counter() - began, time.process_time())"
    )
    with tempfile.TemporaryDirectory(prefix="numba-cache-") as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache}
        return [tuple(map(float, subprocess.run([sys.executable, "-c", code], env=env, check=True,
                                                capture_output=True, text=True).stdout.split()))
                for _ in range(2)]


def retargets(size, runs):
    """Round-robin multi-scale retargets with each face search; prints a table."""
    from hairport import solver
    from hairport.solver.adaptation.problem import constraints
    from hairport.solver.mesh import collision
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import PRESETS, build_character

    per_strand = 50 if size < 200_000 else 100
    source, target = build_character(PRESETS["average-female"]), build_character(PRESETS["heavy-male"])
    hair = generate_groom(source, "long", max(1, round(size / per_strand)), per_strand, seed=0)
    adaptable = solver.preprocess(source, hair, solver.PreprocessOptions(guides=300))
    adaptable.coarse_model, adaptable.fine_source  # noqa: B018 - outside the timings
    options = solver.RetargetOptions(method="multiscale", workers=1)

    inside = {"seconds": 0.0, "calls": 0, "particles": 0}
    call = constraints.BodyDistance.__call__

    def counted(self, points):
        began = time.perf_counter()
        out = call(self, points)
        inside["seconds"] += time.perf_counter() - began
        inside["calls"] += 1
        inside["particles"] += int(out[2].sum())
        return out

    constraints.BodyDistance.__call__ = counted
    rows = {name: [] for name in ("igl", "bvh")}
    results = {}
    saved = backends.CLOSEST_FACE_BACKENDS
    try:
        for _ in range(runs):
            for name in rows:
                backends.CLOSEST_FACE_BACKENDS = (name,)
                collision._LOCAL.__dict__.get("bodies", {}).clear()  # a fresh query on this backend
                inside.update(seconds=0.0, calls=0, particles=0)
                began = time.perf_counter()
                result = solver.retarget(adaptable, target, options)
                rows[name].append((time.perf_counter() - began, result.timings["solve"], dict(inside)))
                results[name] = result.hair.points
    finally:
        backends.CLOSEST_FACE_BACKENDS = saved
        constraints.BodyDistance.__call__ = call
    apart = np.linalg.norm(results["igl"] - results["bvh"], axis=1)
    print(f"multi-scale retarget, {hair.n_particles:,} particles, workers=1, median of {runs}")
    header = (f"{'face search':<14}{'retarget s':>12}{'solve s':>10}{'BodyDistance s':>16}{'calls':>8}"
              f"{'particles':>13}{'us/particle':>13}")
    print(header)
    print("-" * len(header))
    for name, values in rows.items():
        total = statistics.median(v[0] for v in values)
        solve = statistics.median(v[1] for v in values)
        seconds = statistics.median(v[2]["seconds"] for v in values)
        calls, particles = values[-1][2]["calls"], values[-1][2]["particles"]
        print(f"{name:<14}{total:>12.2f}{solve:>10.2f}{seconds:>16.2f}{calls:>8,}{particles:>13,}"
              f"{seconds / max(particles, 1) * 1e6:>13.3f}")
    print(f"results apart: max {apart.max():.2e} m, mean {apart.mean():.2e} m, "
          f"{np.count_nonzero(apart > 1e-9):,} particles beyond 1 nm\n")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--groom", nargs="*", default=["1000x100", "10000x100"], help="strands x particles per strand")
    parser.add_argument("--compile", action="store_true", help="also time compilation and the cached load")
    parser.add_argument("--retarget", type=float, nargs="*", default=[], help="multi-scale retargets of ~N particles")
    args = parser.parse_args()

    from hairport.solver.synthetic.makehuman import PRESETS, build_character

    if args.compile:
        (first, first_cpu), (second, second_cpu) = compile_times()
        print(f"kernel warm-up ({', '.join(m.rsplit('.', 1)[1] for m in WARM_MODULES)}): compile {first:.1f} s "
              f"(process CPU {first_cpu:.1f} s), cached load in a second process {second:.2f} s (CPU {second_cpu:.2f} s, "
              f"the process's imports included)\n")

    character = build_character(PRESETS["heavy-male"])
    vertices, faces = np.asarray(character.vertices, float), np.asarray(character.faces, np.int64)
    igl_query, bvh_query = forced(vertices, faces, "igl"), forced(vertices, faces, "bvh")
    kernels.warm_up()
    print(f"mesh: MakeHuman heavy-male, {len(faces)} faces; {jit.threads()} numba threads; "
          f"median of {args.runs} runs, methods round-robin\n")

    header = (f"{'method':<18}{'N':>10}{'us/point':>10}{'cpu us/pt':>11}{'igl/this':>10}{'faces differ':>14}")
    rng = np.random.default_rng(0)
    for spec in args.groom:
        strands, per_strand = map(int, spec.lower().split("x"))
        previous, points = hair_points(character, strands, per_strand, rng)
        n = len(points)
        hint = bvh_query.signed_distance(previous).faces
        filled = bvh_query.cell_cache()
        bvh_query.signed_distance(previous, cells=filled)
        methods = {
            "igl": lambda: igl_query.signed_distance(points),
            "bvh": lambda: bvh_query.signed_distance(points),
            "bvh hinted": lambda: bvh_query.signed_distance(points, hint=hint),
            "cells, empty": lambda: bvh_query.signed_distance(points, cells=bvh_query.cell_cache()),
            "cells, filled": lambda: bvh_query.signed_distance(points, cells=filled),
        }
        reference = igl_query.signed_distance(points)
        differ = {label: check(reference, method(), label) for label, method in methods.items()}
        walls = {label: [] for label in methods}
        cpus = {label: [] for label in methods}
        for _ in range(args.runs):
            for label, method in methods.items():
                wall, cpu = time.perf_counter(), time.process_time()
                method()
                walls[label].append(time.perf_counter() - wall)
                cpus[label].append(time.process_time() - cpu)
        base = statistics.median(walls["igl"])
        print(f"groom long {spec}: {n:,} particles within {BAND * 100:.0f} cm; "
              f"filled cache: {filled.n_cells:,} cells of {filled.size * 1e3:.0f} mm, "
              f"{filled.n_candidates / max(filled.n_cells, 1):.1f} candidates per cell, "
              f"{filled.nbytes / 2**20:.1f} MiB")
        print(header)
        print("-" * len(header))
        for label in methods:
            wall, cpu = statistics.median(walls[label]), statistics.median(cpus[label])
            print(f"{label:<18}{n:>10,}{wall / n * 1e6:>10.3f}{cpu / n * 1e6:>11.3f}{base / wall:>10.2f}"
                  f"{differ[label]:>14,}")
        print()
    for size in args.retarget:
        retargets(int(size), args.runs)


if __name__ == "__main__":
    main()
