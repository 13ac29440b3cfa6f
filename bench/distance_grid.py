"""Benchmark of the distance-grid broad phase in solver/mesh/distance_grid.py.

Prints, for the MakeHuman "heavy-male" body (13,380 vertices, 26,756 faces) and its
procedural ``long`` groom, the median over runs of:

* grid build: :meth:`DistanceGrid.build` with the defaults (5 mm, 2 cm margin, exact
  within 2.5 cm, coarse to fine) and, with ``--full-exact``, with every node queried
  exactly (``exact_band=inf``; one run: it takes over a minute), and how many nodes each
  queried exactly (all levels);
* per workload (groom particles, and ``--strands``: synthetic strands leaving the body,
  100 particles 3 mm apart, most of them far from it): the exact signed distance on all
  points (:meth:`MeshQuery.signed_distance`, the baseline), ``near_mask`` alone, and
  ``near_mask`` + the exact query on the near subset only (the broad phase end to end);
  the fraction of points near; the ratio baseline / broad phase in the same run (larger
  is better). The broad phase is checked against the baseline every time: no point with
  ``|d| < band`` is missed, and the near subset's distances equal the baseline's.

Times are wall-clock medians; the CPU column is process time, steadier on a shared machine.

    python bench/distance_grid.py [--runs 3] [--groom 5000x20 10000x100] [--strands 1000000] [--bands 0.01] [--full-exact]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from geometry import strand_points, timed  # bench/geometry.py, beside this script

from hairport.solver.mesh import distance_grid
from hairport.solver.mesh.distance_grid import DistanceGrid, near_mask
from hairport.solver.mesh.query import MeshQuery


def broad_phase(grid, query, band):
    """Exact signed distance of the points that may be within ``band``: (indices, distances)."""

    def call(points):
        near = np.flatnonzero(near_mask(grid, points, band))
        return near, query.signed_distance(points[near]).distance

    return call


def counting_build(query, **kwargs):
    """DistanceGrid.build, and how many nodes it queried exactly (all levels)."""
    count = [0]
    exact_values = distance_grid._exact_values

    def counted(q, origin, spacing, shape, flat):
        count[0] += len(flat)
        return exact_values(q, origin, spacing, shape, flat)

    distance_grid._exact_values = counted
    try:
        grid = DistanceGrid.build(query, **kwargs)
    finally:
        distance_grid._exact_values = exact_values
    return grid, count[0]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--groom", nargs="*", default=["5000x20", "10000x100"], help="strands x particles per strand")
    parser.add_argument("--strands", type=int, nargs="*", default=[1_000_000], help="synthetic strand particles")
    parser.add_argument("--bands", type=float, nargs="+", default=[0.01], help="near_mask band (m)")
    parser.add_argument("--spacing", type=float, default=distance_grid.DEFAULT_GRID_SPACING)
    parser.add_argument("--full-exact", action="store_true", help="also time the build with every node exact (slow)")
    args = parser.parse_args()

    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import PRESETS, build_character

    character = build_character(PRESETS["heavy-male"])
    vertices, faces = np.asarray(character.vertices, float), np.asarray(character.faces, np.int64)
    query = MeshQuery(vertices, faces)
    query.signed_distance(vertices[:1])  # the tree, outside the timings
    print(f"mesh: MakeHuman heavy-male, {len(vertices)} vertices, {len(faces)} faces; median of {args.runs} runs\n")

    header = f"{'grid build':<40}{'shape':>18}{'spacing':>10}{'exact queries':>15}{'wall s':>10}{'cpu s':>10}"
    print(header)
    print("-" * len(header))
    builds = [("coarse to fine (exact within 2.5 cm)", dict(exact_band=distance_grid.DEFAULT_EXACT_BAND), args.runs)]
    if args.full_exact:
        builds.append(("every node exact (1 run)", dict(exact_band=np.inf), 1))
    grid = None
    for label, kwargs, runs in builds:
        w, c = time.perf_counter(), time.process_time()
        built, queried = counting_build(query, spacing=args.spacing, **kwargs)
        wall, cpu = time.perf_counter() - w, time.process_time() - c
        grid = grid or built
        if runs > 1:  # the counted build was the warm-up
            wall, cpu = timed(lambda: DistanceGrid.build(query, spacing=args.spacing, **kwargs), runs, warm_up=False)
        shape = "x".join(map(str, built.shape))
        print(f"{label:<40}{shape:>18}{built.spacing * 1e3:>8.1f}mm{queried:>15,}{wall:>10.2f}{cpu:>10.2f}")
    print()

    rng = np.random.default_rng(0)
    workloads = []
    for spec in args.groom:
        strands, per_strand = map(int, spec.lower().split("x"))
        points = generate_groom(character, "long", strands, per_strand, seed=0).points
        workloads.append((f"groom long {strands}x{per_strand}", points))
    workloads += [("strands leaving the body", strand_points(vertices, n, rng)) for n in args.strands]

    header = f"{'workload':<28}{'N':>10}{'band':>8}{'near':>8}  {'method':<30}{'wall s':>9}{'cpu s':>9}{'exact/new':>10}"
    print(header)
    print("-" * len(header))
    for name, points in workloads:
        baseline = query.signed_distance(points).distance
        base_wall, base_cpu = timed(lambda: query.signed_distance(points), args.runs)
        for band in args.bands:
            broad = broad_phase(grid, query, band)
            near, distance = broad(points)
            missed = int(np.count_nonzero(np.abs(baseline) < band) - np.count_nonzero(np.abs(distance) < band))
            assert missed == 0 and np.array_equal(distance, baseline[near]), "the broad phase lost a near point"
            share = len(near) / len(points)
            mask_wall, mask_cpu = timed(lambda: near_mask(grid, points, band), args.runs)
            wall, cpu = timed(lambda: broad(points), args.runs)
            lead = f"{name:<28}{len(points):>10}{band * 100:>6.1f}cm{share:>8.1%}  "
            pad = " " * len(lead)
            print(f"{lead}{'exact on all (baseline)':<30}{base_wall:>9.3f}{base_cpu:>9.3f}{1.0:>10.2f}")
            print(f"{pad}{'near_mask only':<30}{mask_wall:>9.3f}{mask_cpu:>9.3f}{base_wall / mask_wall:>10.2f}")
            print(f"{pad}{'near_mask + exact on near':<30}{wall:>9.3f}{cpu:>9.3f}{base_wall / wall:>10.2f}")
            really = np.mean(np.abs(baseline) < band)
            print(f"{pad}{f'(|d| < band in fact: {really:.1%})':<30}")
        print()


if __name__ == "__main__":
    main()
