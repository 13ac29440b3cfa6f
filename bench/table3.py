"""The paper's Table 3 on this machine: root-density change of hairline edits.

For each groom (MakeHuman source character, style, strand count) the roots are carried to a
target character (same topology: same faces and barycentric coordinates, as after the
initial transfer) and relocated there for two edits, ``straight`` and ``widows-peak``
(amount 1), by

* ours: the embedded membrane (Eq. 15),
* harmonic: a harmonic displacement of the scalp in the parameterization,
* RBF(2D): a thin-plate RBF displacement in the parameterization,

all in the LSCM parameterization as in the paper's table, and reports the L1 (mean) and
L-infinity (max) of the relative change of root density per scalp triangle (min / max /
avg over the grooms per edit). Then, in the same run:

* the membrane in the harmonic, LSCM and ARAP parameterizations: largest mean distance
  between their relocated roots (Fig. 17);
* the 3D thin-plate RBF with reprojection (Fig. 13);
* the relocation time for scalps of 10^4 and 10^5 roots (median of ``--runs``), split into
  scalp + chart, membrane and root moves.

    python bench/table3.py [--strands 3000] [--runs 3]

Prints tables; not a test.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from hairport.solver.body.head_frame import head_frame
from hairport.solver.hairline.edit import HairlineEdit
from hairport.solver.hairline.relocation import relocate_roots
from hairport.solver.synthetic.groom import generate_groom, sample_roots, scalp_faces
from hairport.solver.synthetic.makehuman import PRESETS, build_character

#: (source character, target character, style, seed)
GROOMS = [
    ("average-female", "heavy-male", "short", 0),
    ("average-female", "heavy-male", "long", 1),
    ("average-female", "slim-tall-female", "fringe", 2),
    ("average-male", "average-female", "wavy", 3),
    ("heavy-male", "average-male", "curly", 4),
    ("slim-tall-female", "average-female", "short", 5),
    ("average-male", "child", "long", 6),
    ("child", "average-male", "fringe", 7),
]
EDITS = {"S": "straight", "W": "widows-peak"}
METHODS = {"Our": "membrane", "Harmonic": "harmonic", "RBF(2D)": "rbf2d"}
#: particles per strand of the benchmark grooms: only the roots matter here
PARTICLES = 4


def groom_roots(source, style: str, strands: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(faces, barycentric) of a groom's roots on its source."""
    from hairport.solver.mesh.query import MeshQuery
    from hairport.solver.mesh.triangles import barycentric_coordinates

    hair = generate_groom(source, style, strands, PARTICLES, seed=seed)
    points = hair.points[hair.roots]
    found = MeshQuery(source.vertices, source.faces).signed_distance(points)
    return found.faces, barycentric_coordinates(found.closest, source.vertices[source.faces[found.faces]])


def table(rows: list[list[str]], header: list[str]) -> str:
    widths = [max(len(str(r[i])) for r in rows + [header]) for i in range(len(header))]
    line = lambda r: "| " + " | ".join(str(c).rjust(w) for c, w in zip(r, widths)) + " |"  # noqa: E731
    return "\n".join([line(header), "|" + "|".join("-" * (w + 2) for w in widths) + "|"] + [line(r) for r in rows])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--strands", type=int, default=3000)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--sizes", type=float, nargs="*", default=[1e4, 1e5])
    args = parser.parse_args()

    characters = {name: build_character(PRESETS[name]) for name in PRESETS}
    results = {}  # (groom, edit, method) -> report
    spread = []  # (groom, edit, largest mean distance between parameterizations)
    per_groom = []
    for number, (source, target, style, seed) in enumerate(GROOMS):
        faces, weights = groom_roots(characters[source], style, args.strands, seed)
        character = characters[target]
        for key, edit in EDITS.items():
            for label, method in {**METHODS, "RBF(3D)": "rbf3d"}.items():
                moved = relocate_roots(character, faces, weights, HairlineEdit(preset=edit, method=method,
                                                                             parameterization="lscm"))
                results[number, key, label] = moved.report
            roots = {
                param: relocate_roots(character, faces, weights, HairlineEdit(preset=edit, parameterization=param)).roots
                for param in ("harmonic", "lscm", "arap")
            }
            pairs = [("harmonic", "lscm"), ("harmonic", "arap"), ("lscm", "arap")]
            spread.append(max(float(np.linalg.norm(roots[a] - roots[b], axis=1).mean()) for a, b in pairs))
            ours = results[number, key, "Our"]
            per_groom.append([
                f"{source} -> {target}, {style}", key, ours["membrane_triangles"], f"{100 * ours['max_travel_m']:.1f}",
                *[f"{results[number, key, label]['density_change_l1']:.3f}" for label in (*METHODS, "RBF(3D)")],
                f"{1000 * spread[-1]:.2f}", f"{ours['seconds']:.2f}",
            ])
    print(f"Per groom ({args.strands} strands each; LSCM parameterization; edits at amount 1):\n")
    print(table(per_groom, ["groom", "edit", "scalp triangles", "largest root move (cm)", "L1 Our", "L1 Harmonic",
                            "L1 RBF(2D)", "L1 RBF(3D)", "param. spread (mm)", "relocation (s)"]))

    rows = []
    for key in EDITS:
        for stat, reduce in (("min", min), ("max", max), ("avg.", statistics.mean)):
            row = [f"{stat}({key})"]
            for metric in ("density_change_l1", "density_change_linf"):
                row += [f"{reduce(results[g, key, label][metric] for g in range(len(GROOMS))):.3f}" for label in METHODS]
            rows.append(row)
    print(f"\nTable 3 ({len(GROOMS)} grooms x {len(EDITS)} edits):\n")
    print(table(rows, ["", *[f"L1 {m}" for m in METHODS], *[f"Linf {m}" for m in METHODS]]))
    wins = sum(results[g, k, "Our"]["density_change_l1"] < min(results[g, k, m]["density_change_l1"]
                                                             for m in ("Harmonic", "RBF(2D)"))
               for g in range(len(GROOMS)) for k in EDITS)
    print(f"\nours has the lowest L1 in {wins} of {len(GROOMS) * len(EDITS)} groom x edit combinations")
    print(f"parameterization spread (membrane, harmonic vs LSCM vs ARAP, mean root distance): "
          f"min {1000 * min(spread):.2f} mm, max {1000 * max(spread):.2f} mm, avg {1000 * statistics.mean(spread):.2f} mm")

    # relocation time for dense scalps
    character = characters["heavy-male"]
    source = characters["average-female"]
    candidates = scalp_faces(source, head_frame(source))
    timing = []
    for size in args.sizes:
        faces, weights, _ = sample_roots(source, candidates, int(size), np.random.default_rng(0))
        for edit in EDITS.values():
            reports = [relocate_roots(character, faces, weights, HairlineEdit(preset=edit)).report
                       for _ in range(args.runs)]
            med = lambda key: statistics.median(r[key] for r in reports)  # noqa: E731
            timing.append([f"{int(size):,}", edit, reports[0]["membrane_triangles"], f"{med('seconds'):.2f}",
                           f"{med('scalp_seconds'):.2f}", f"{med('deform_seconds'):.2f}", f"{med('roots_seconds'):.2f}",
                           f"{reports[0]['density_change_l1']:.3f}"])
    print(f"\nRelocation time (median of {args.runs}; roots sampled uniformly on the scalp, average female -> "
          "heavy male, harmonic parameterization):\n")
    print(table(timing, ["roots", "edit", "scalp triangles", "relocation (s)", "scalp + chart (s)", "membrane (s)",
                         "roots (s)", "L1"]))


if __name__ == "__main__":
    began = time.perf_counter()
    main()
    print(f"\n(total {time.perf_counter() - began:.0f} s)")
