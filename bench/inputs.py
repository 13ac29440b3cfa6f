"""Benchmark of the canonical-frame stage (solver/inputs.py): what bringing a source character and
its groom into hairport's frame costs, next to preprocessing them.

For procedural "long" grooms on the MakeHuman average female, written as a file in millimetres
with Z up would hold them (nothing stated: units and axes inferred), prints the median over runs
of :func:`canonical_source` without and with the input report's measurements (one signed-distance
query of every particle), and of :func:`preprocess` for scale.

    python bench/inputs.py [--sizes 1e4 1e5 1e6] [--runs 3]
"""

from __future__ import annotations

import argparse
import statistics
import time

from hairport import solver
from hairport.solver.model.character import Character, Skeleton
from hairport.solver.model.frame import InputFrame
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import PRESETS, build_character

#: particles per strand of the grooms
PARTICLES = 50
#: the frame the inputs are written in
FRAME = InputFrame("mm", "z", "-y")


def in_frame(character: Character, hair: solver.Hair) -> tuple[Character, solver.Hair]:
    scale, s = FRAME.scale, character.skeleton
    skeleton = Skeleton(s.names, s.parents, FRAME.axes_out(s.heads) / scale, FRAME.axes_out(s.tails) / scale)
    body = Character(FRAME.axes_out(character.vertices) / scale, character.faces, skeleton, character.weights)
    return body, hair.with_points(FRAME.axes_out(hair.points) / scale)


def median_seconds(call, runs: int) -> float:
    times = []
    for _ in range(runs):
        began = time.perf_counter()
        call()
        times.append(time.perf_counter() - began)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=float, nargs="+", default=[1e4, 1e5, 1e6])
    parser.add_argument("--runs", type=int, default=3)
    args = parser.parse_args()
    source = build_character(PRESETS["average-female"])
    print("| particles | strands | canonical_source s | with the input report s | preprocess s | frame found |")
    print("|---|---|---|---|---|---|")
    for size in args.sizes:
        strands = int(size) // PARTICLES
        hair = generate_groom(source, "long", strands, PARTICLES, seed=0)
        body, groom = in_frame(source, hair)
        bare = median_seconds(lambda: solver.canonical_source(body, groom, measure=False), args.runs)
        inputs = solver.canonical_source(body, groom)
        full = median_seconds(lambda: solver.canonical_source(body, groom), args.runs)
        pre = median_seconds(lambda: solver.preprocess(inputs.source, inputs.hair), args.runs)
        print(f"| {hair.n_particles:,} | {strands:,} | {bare:.2f} | {full:.2f} | {pre:.2f} | "
              f"{inputs.frame.describe()} |")


if __name__ == "__main__":
    main()
