"""How close a retarget onto a target of another topology comes to the same-topology retarget.

The source is MakeHuman ``average-female`` with procedural grooms; each target preset is built
twice: as MakeHuman makes it (the source's topology: the reference retarget) and remeshed to
another topology (:func:`hairport.solver.synthetic.remesh.remesh`, isotropic: other vertex
count, order and triangles), which the retarget wraps (:mod:`hairport.solver.wrapping`). Per
target, density and groom the table gives the wrapped result against the reference:

* ``mean`` / ``p95``: distance of each particle to the reference's (mm);
* ``inside``: particles inside the remeshed target; ``root``: largest root distance to its
  surface (mm);
* ``d angle``: the wrapped result's mean segment angle (to the source groom) minus the
  reference's (rad);
* ``resid``: the wrap's symmetric residual over the fitted region, mean (mm); ``wrap s`` /
  ``total s``: the wrap's and the whole retarget's wall time.

``--landmarks N`` gives the wrap N landmarks as a user would place them, at known points: the
source head's vertices farthest along :data:`LANDMARK_DIRECTIONS` (the first N), paired with the
same vertices of the preset, the points a same-topology retarget maps them to.

``--presets average-female`` is the control: the source body itself remeshed, where the
correspondence is known and the wrap alone is measured. The last lines give the worst of each column and how many cases meet the bounds of
:data:`BOUNDS`.

    python bench/wrap_fidelity.py [--presets heavy-male child ...] [--sizes 5000 20000 100000]
                                  [--styles short long fringe] [--strands 400] [--particles 20]
                                  [--landmarks 0..11]

Prints tables; not a test.
"""

from __future__ import annotations

import argparse
import functools
import platform
import time
from datetime import date

import numpy as np

from hairport.solver import pipeline
from hairport.solver.body.head_frame import head_frame
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.metrics import mean_segment_angle
from hairport.solver.model.landmarks import LandmarkPairs
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import PRESETS, build_character
from hairport.solver.synthetic.remesh import remeshed_character

SOURCE = "average-female"
TARGETS = tuple(name for name in PRESETS if name != SOURCE)
#: the bounds a wrapped retarget is held to against the same-topology one: mean and p95 particle
#: distance (m), particles inside, root distance to the surface (m), segment angle difference (rad)
BOUNDS = {"mean": 1.5e-3, "p95": 5e-3, "inside": 0, "root": 1e-4, "angle": 0.01}
#: where ``--landmarks`` places its points: directions in the source's head frame (up, front, side)
LANDMARK_DIRECTIONS = {
    "crown": (1, 0, 0), "nape": (0, -1, 0), "left": (0, 0, 1), "right": (0, 0, -1), "front_top": (1, 1, 0),
    "back_top": (1, -1, 0), "left_top": (1, 0, 1), "right_top": (1, 0, -1), "back_left": (0.3, -1, 1),
    "back_right": (0.3, -1, -1), "forehead": (0.3, 1, 0),
}


@functools.lru_cache(maxsize=None)
def character(preset: str):
    return build_character(PRESETS[preset])


@functools.lru_cache(maxsize=None)
def adaptable(style: str, strands: int, particles: int):
    source = character(SOURCE)
    return pipeline.preprocess(source, generate_groom(source, style, strands, particles, seed=0))


@functools.lru_cache(maxsize=None)
def reference(preset: str, style: str, strands: int, particles: int):
    return pipeline.retarget(adaptable(style, strands, particles), character(preset))


@functools.lru_cache(maxsize=None)
def landmark_vertices(count: int) -> tuple[tuple[str, ...], np.ndarray]:
    """Names and source vertex ids of the first ``count`` of :data:`LANDMARK_DIRECTIONS`."""
    source = character(SOURCE)
    frame = head_frame(source)
    head = np.flatnonzero(frame.head_vertices)
    local = frame.local(source.vertices[head])
    unit = local / np.linalg.norm(local, axis=1, keepdims=True)
    names = tuple(LANDMARK_DIRECTIONS)[:count]
    ids = [head[np.argmax(unit @ (np.asarray(LANDMARK_DIRECTIONS[n]) / np.linalg.norm(LANDMARK_DIRECTIONS[n])))]
           for n in names]
    return names, np.asarray(ids)


def landmarks(preset: str, count: int) -> LandmarkPairs | None:
    """``count`` landmarks on the source and the preset (:func:`landmark_vertices`), None for 0."""
    if count == 0:
        return None
    names, ids = landmark_vertices(count)
    return LandmarkPairs(names, character(SOURCE).vertices[ids], character(preset).vertices[ids])


def measure(preset: str, size: int, style: str, strands: int, particles: int, marks: int = 0) -> dict:
    groom = adaptable(style, strands, particles)
    expected = reference(preset, style, strands, particles)
    target = remeshed_character(character(preset), size, seed=1)
    began = time.perf_counter()
    result = pipeline.retarget(groom, target, pipeline.RetargetOptions(landmarks=landmarks(preset, marks)))
    seconds = time.perf_counter() - began
    points, hair = result.hair.points, groom.hair
    distance = np.linalg.norm(points - expected.hair.points, axis=1)
    query = MeshQuery(target.vertices, target.faces)
    signed = query.signed_distance(points).distance
    segments = hair.segments
    return {
        "mean": float(distance.mean()), "p95": float(np.percentile(distance, 95)),
        "inside": int(np.count_nonzero(signed[~hair.at_root] < 0)),
        "root": float(np.abs(signed[hair.roots]).max()),
        "angle": mean_segment_angle(points, hair.points, segments) - mean_segment_angle(expected.hair.points, hair.points, segments),
        "resid": result.metrics["wrap"]["residual_m"]["mean"], "wrap": result.timings.get("wrap", 0.0), "total": seconds,
    }


def meets(row: dict) -> bool:
    return (row["mean"] <= BOUNDS["mean"] and row["p95"] <= BOUNDS["p95"] and row["inside"] <= BOUNDS["inside"]
            and row["root"] <= BOUNDS["root"] and abs(row["angle"]) <= BOUNDS["angle"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--presets", nargs="+", default=TARGETS, choices=tuple(PRESETS))
    parser.add_argument("--sizes", nargs="+", type=int, default=[5000, 20000, 100000])
    parser.add_argument("--styles", nargs="+", default=["short", "long", "fringe"])
    parser.add_argument("--strands", type=int, default=400)
    parser.add_argument("--particles", type=int, default=20)
    parser.add_argument("--landmarks", type=int, default=0, choices=range(len(LANDMARK_DIRECTIONS) + 1),
                        metavar="N", help="landmarks given to the wrap (0-11)")
    args = parser.parse_args()
    print(f"# {platform.node()} {platform.processor() or platform.machine()}, {date.today()}: "
          f"{SOURCE} -> remeshed presets, {args.strands} strands x {args.particles} particles, "
          f"{args.landmarks} landmarks")
    header = f"{'target':<16} {'verts':>6} {'style':<7} {'mean':>5} {'p95':>5} {'inside':>6} {'root':>6} {'d angle':>8} {'resid':>5} {'wrap s':>6} {'total s':>7}"
    print(header)
    rows = []
    for preset in args.presets:
        for size in args.sizes:
            for style in args.styles:
                row = measure(preset, size, style, args.strands, args.particles, args.landmarks)
                rows.append(row)
                print(f"{preset:<16} {size:>6} {style:<7} {row['mean'] * 1e3:5.2f} {row['p95'] * 1e3:5.2f} {row['inside']:>6} "
                      f"{row['root'] * 1e3:6.3f} {row['angle']:+8.4f} {row['resid'] * 1e3:5.2f} {row['wrap']:6.2f} {row['total']:7.2f}",
                      flush=True)
    worst = {key: max(row[key] for row in rows) for key in ("mean", "p95", "inside", "root")}
    worst_angle = max(abs(row["angle"]) for row in rows)
    print(f"worst: mean {worst['mean'] * 1e3:.2f} mm, p95 {worst['p95'] * 1e3:.2f} mm, inside {worst['inside']}, "
          f"root {worst['root'] * 1e3:.3f} mm, |d angle| {worst_angle:.4f} rad")
    print(f"within bounds (mean <= {BOUNDS['mean'] * 1e3} mm, p95 <= {BOUNDS['p95'] * 1e3} mm, 0 inside, "
          f"root <= {BOUNDS['root'] * 1e3} mm, |d angle| <= {BOUNDS['angle']}): {sum(map(meets, rows))} / {len(rows)}")


if __name__ == "__main__":
    main()
