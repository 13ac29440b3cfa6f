"""A body that moves, frame to frame (a sequence): its queries moved against built anew.

For the MakeHuman average female moved to a later body of the same mesh (a step of ``--steps`` along the sweep to
the heavy male, as ``bench/sequence.py``'s frames, and the whole sweep in one step), in this process, the median over
``--runs`` of:

* the compiled face search: :func:`~hairport.solver.mesh.bvh.build_tree` on the moved vertices against
  :func:`~hairport.solver.mesh.bvh.refit_tree` of the first body's tree; the two trees' box area (the surface area
  heuristic's cost) over the first build's, and the signed distance of 10^5 points within 1 cm of the moved body in
  each;
* the body's collision query, ready for queries (its separating faces found, its face search and tables made):
  built alone (:func:`~hairport.solver.mesh.collision.collision_query`) against moved from the first body's
  (``moved_from=``), each in a thread of its own so that no cached query answers.

    python bench/moved_body.py [--runs 5] [--steps 24]

Prints a table; not a test. Times are wall-clock seconds on this machine.
"""

from __future__ import annotations

import argparse
import statistics
import threading
import time

import numpy as np

from hairport.solver import kernels
from hairport.solver.mesh import bvh
from hairport.solver.mesh.collision import collision_query


def bodies(steps: int):
    """The first body, the next one of a ``steps``-step sweep, and the last (``(V, 3)`` vertices each) and the faces."""
    from hairport.solver.synthetic.makehuman import PRESETS, build_character
    from hairport.solver.synthetic.makehuman.macros import blend_params

    first, last = PRESETS["average-female"], PRESETS["heavy-male"]
    built = [build_character(blend_params(first, last, t)) for t in (0.0, 1.0 / steps, 1.0)]
    return [body.vertices for body in built], built[0].faces


def median_seconds(call, runs: int) -> float:
    seconds = []
    for _ in range(runs):
        began = time.perf_counter()
        call()
        seconds.append(time.perf_counter() - began)
    return statistics.median(seconds)


def ready(query, points):
    """The query with its face search and tables made (one query)."""
    query.signed_distance(points[:1])
    return query


def in_thread(call):
    out = []
    thread = threading.Thread(target=lambda: out.append(call()))
    thread.start()
    thread.join()
    return out[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--steps", type=int, default=24)
    args = parser.parse_args()
    kernels.warm_up()
    (first, step, last), faces = bodies(args.steps)
    tree = bvh.build_tree(first, faces)
    rng = np.random.default_rng(0)
    first_query = ready(collision_query(first, faces), first)
    print(f"MakeHuman average female ({len(faces):,} faces) moved; median of {args.runs} runs\n")
    print("| move | largest vertex motion | build tree s | refit s | box area, built / refit | "
          "10^5 queries s, built / refit | collision query built s | moved s |")
    print("|---|---|---|---|---|---|---|---|")
    for name, moved in ((f"one step of {args.steps}", step), ("the whole sweep", last)):
        points = moved[rng.integers(0, len(moved), 100_000)] + rng.normal(size=(100_000, 3)) * 0.01
        built, refit = bvh.build_tree(moved, faces), bvh.refit_tree(tree, moved, faces)
        build_s = median_seconds(lambda moved=moved: bvh.build_tree(moved, faces), args.runs)
        refit_s = median_seconds(lambda moved=moved: bvh.refit_tree(tree, moved, faces), args.runs)
        query_built = median_seconds(lambda built=built, points=points: bvh.closest_points(built, points), args.runs)
        query_refit = median_seconds(lambda refit=refit, points=points: bvh.closest_points(refit, points), args.runs)
        fresh_s = median_seconds(lambda moved=moved: in_thread(lambda: ready(collision_query(moved, faces), moved)),
                                 args.runs)
        moved_s = median_seconds(lambda moved=moved: in_thread(lambda: ready(
            collision_query(moved, faces, moved_from=first_query), moved)), args.runs)
        motion = float(np.linalg.norm(moved - first, axis=1).max())
        print(f"| {name} | {motion * 1e3:.1f} mm | {build_s:.4f} | {refit_s:.4f} | "
              f"{built.built_area / tree.built_area:.2f} / {bvh.node_area(refit.boxes) / tree.built_area:.2f} | "
              f"{query_built:.3f} / {query_refit:.3f} | {fresh_s:.3f} | {moved_s:.3f} |")


if __name__ == "__main__":
    main()
