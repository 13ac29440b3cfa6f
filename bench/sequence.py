"""A hairstyle onto a sequence of bodies: what a warm frame costs against a cold retarget, and how it differs.

The sequence is a MakeHuman morph sweep: the average female (the groom's source) to the heavy male in ``--steps``
steps of every slider (``makehuman.macros.blend_params``), as a character customiser's sliders move; its largest
vertex step is printed. For each groom size (a "long" groom, as ``bench/table4.py``'s), in a fresh process:

* the sequence retargeted frame by frame (``solver.sequence.retarget_sequence``: warm frames, no temporal term unless
  ``--temporal``), each frame's wall-clock seconds;
* a cold retarget (``solver.retarget``) of every ``--cold-every``-th frame, its seconds, and the mean distance
  between the two results of that frame (the body's collision query built for it, not the one its warm frame kept:
  ``mesh.collision.forget_bodies``);
* per frame: particles inside the body, and the coherence figures (the largest particle jump from the previous
  frame against twice the body's largest motion near the hair plus 1 mm);
* where the time goes: each stage's median seconds over the later frames and over the cold retargets (and the part
  of the two levels spent on segments through the body);
* ``--remesh V``: the sweep on another mesh than the groom's source (remeshed to about ``V`` vertices, one mesh
  for every frame): the first frame wrapped, the later ones carrying its wrap; each cold retarget wraps its frame
  itself, and both are also compared with a retarget onto the sweep's own frame (the exact correspondence);
* ``--spacing W``: the spacing term's weight, for the warm frames and the cold retargets alike (by default a
  sequence's own, ``solver.options.SEQUENCE_SPACING``; 0 is Eq. 1);
* with ``--tight``, the last frame also retargeted cold at a tenth of the energy and step tolerances: the mean
  distance of the default cold retarget and of the warm frame to it (the solver's tolerance, against the warm
  frames' own distance).

The kernels are warmed first, and one retarget runs before anything is timed. Medians: the later frames' (all but
the first, which is the source's own body) and the cold retargets'; their ratio is the figure the issue's target
names (at most 0.25).

    python bench/sequence.py [--sizes 1e5 1e6] [--steps 24] [--cold-every 4] [--temporal 0] [--spacing 3] [--tight]
                             [--remesh 20000]

Prints a table; not a test. Times are wall-clock seconds on this machine.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from table4 import SOURCE, STYLE, TARGET, _machine, groom_shape  # noqa: E402


def sweep(steps: int):
    """The ``steps + 1`` bodies of the sweep, the first the source."""
    from hairport.solver.synthetic.makehuman import PRESETS, build_character
    from hairport.solver.synthetic.makehuman.macros import blend_params

    first, last = PRESETS[SOURCE], PRESETS[TARGET]
    return [build_character(blend_params(first, last, k / steps), name=f"sweep {k}/{steps}") for k in range(steps + 1)]


#: ``--tight``: the reference retarget's tolerances, this times the defaults (energy and step)
TIGHT_FACTOR = 0.1


#: a retarget's stages, as its timings name them, in the order they run
STAGES = ("wrap", "prepare", "initial_transfer", "distance_grid", "coarse_solve", "fine_solve", "penetration_check",
          "metrics")


def stage_seconds(result) -> dict:
    """A retarget's seconds per stage (:data:`STAGES`, 0 for one it did not run), and the part of its two levels
    spent on segments through the body (``segment_rounds``: finding them and solving their windows again)."""
    seconds = {stage: float(result.timings.get(stage, 0.0)) for stage in STAGES}
    report = result.solve
    seconds["segment_rounds"] = float((report.coarse.segment_seconds if report.coarse else 0.0)
                                      + sum(chunk.segment_seconds for chunk in report.fine))
    return seconds


def remeshed_sweep(bodies: list, vertices: int) -> list:
    """The sweep on another mesh: frame 0 remeshed to about ``vertices`` vertices, each of them carried through the
    sweep at its place on the sweep's own faces (so the frames are one mesh, and the sweep's own frames give the
    exact correspondence)."""
    from hairport.solver.mesh.query import MeshQuery
    from hairport.solver.mesh.triangles import barycentric_coordinates, interpolate_barycentric
    from hairport.solver.model.character import Character
    from hairport.solver.synthetic.remesh import remeshed_character

    first = bodies[0]
    remeshed = remeshed_character(first, vertices, seed=0)
    on_first = MeshQuery(first.vertices, first.faces).signed_distance(remeshed.vertices)
    weights = barycentric_coordinates(on_first.closest, first.vertices[first.faces[on_first.faces]])
    return [Character(interpolate_barycentric(body.vertices, body.faces, on_first.faces, weights), remeshed.faces,
                      name=f"{body.name} remeshed") for body in bodies]


def measure(particles: int, steps: int, cold_every: int, temporal: float, tight: bool = False,
            spacing: float = 0.0, remesh: int | None = None) -> dict:
    """In this process: the sequence and the cold retargets of one groom size."""
    from hairport import solver
    from hairport.solver import kernels, sequence
    from hairport.solver.mesh.collision import forget_bodies
    from hairport.solver.synthetic.groom import generate_groom

    kernels.warm_up()
    own = sweep(steps)
    bodies = own if remesh is None else remeshed_sweep(own, remesh)
    adaptable = solver.preprocess(own[0], generate_groom(own[0], STYLE, *groom_shape(particles), seed=0))
    solver.retarget(adaptable, bodies[1])  # the first retarget of an artifact builds what it keeps
    forget_bodies()  # ... and the sequence's frame 1 builds its own body's queries
    frames, last_cold = [], None
    options = solver.RetargetOptions(spacing=spacing)  # the warm frames' and the cold retargets' alike
    for result in sequence.retarget_sequence(adaptable, bodies, options, sequence.SequenceOptions(temporal=temporal)):
        number = result.metrics["frame"]
        row = {"frame": number, "seconds": result.timings["frame"],
               "inside": int(result.metrics["penetrating_particles"]),
               "crossing": int(result.metrics["crossing_segments"]["count"]), **result.metrics.get("coherence", {})}
        row.pop("pops", None)
        row["stages"] = stage_seconds(result)
        if number % cold_every == 0 and number > 0:
            forget_bodies()  # cold: the body's collision query built, not the one the warm frame just kept
            began = time.perf_counter()
            cold = solver.retarget(adaptable, bodies[number], options)
            row["cold_seconds"] = time.perf_counter() - began
            row["cold_stages"] = stage_seconds(cold)
            row["mean_to_cold_m"] = float(np.linalg.norm(result.hair.points - cold.hair.points, axis=1).mean())
            if remesh is not None:  # both against the sweep's own mesh, where no wrap is needed
                exact = solver.retarget(adaptable, own[number], options).hair.points
                row["warm_to_own_m"] = float(np.linalg.norm(result.hair.points - exact, axis=1).mean())
                row["cold_to_own_m"] = float(np.linalg.norm(cold.hair.points - exact, axis=1).mean())
            row["cold_inside"] = int(cold.metrics["penetrating_particles"])
            last_cold = cold if number == steps else None
        frames.append(row)
    reference = tight_reference(adaptable, bodies[-1], options, result, last_cold) if tight else None
    step = max(float(np.linalg.norm(bodies[k + 1].vertices - bodies[k].vertices, axis=1).max()) for k in range(steps))
    return {"particles": adaptable.hair.n_particles, "frames": frames, "largest_vertex_step_m": step,
            "tight": reference}


def tight_reference(adaptable, body, options, warm, cold) -> dict:
    """The last frame retargeted cold with tolerances TIGHT_FACTOR times the defaults: how far the default cold
    retarget and the warm frame are from it (is the distance between them the solver's tolerance, or the warm
    frames' own?), and the three results' energies (Eq. 1 per particle)."""
    from dataclasses import replace

    from hairport import solver

    tight = solver.retarget(adaptable, body, replace(options, energy_tolerance=TIGHT_FACTOR * options.energy_tolerance,
                                                     step_tolerance=TIGHT_FACTOR * options.step_tolerance))
    cold = cold if cold is not None else solver.retarget(adaptable, body, options)
    energy = "energy_total_per_particle"
    return {"warm_to_tight_m": float(np.linalg.norm(warm.hair.points - tight.hair.points, axis=1).mean()),
            "cold_to_tight_m": float(np.linalg.norm(cold.hair.points - tight.hair.points, axis=1).mean()),
            "energies": [float(result.metrics[energy]) for result in (warm, cold, tight)]}


def table(result: dict) -> str:
    frames = result["frames"]
    lines = [f"{result['particles']:,} particles, {len(frames)} frames (largest vertex step "
             f"{1e3 * result['largest_vertex_step_m']:.1f} mm)",
             "| frame | warm s | cold s | warm / cold | mean to cold mm | inside | crossing | jump mm | bound mm | beyond |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for row in frames:
        cold = row.get("cold_seconds")
        compared = ["", "", ""] if cold is None else [f"{cold:.2f}", f"{row['seconds'] / cold:.2f}",
                                                      f"{1e3 * row['mean_to_cold_m']:.3f}"]
        lines.append(
            f"| {row['frame']} | {row['seconds']:.2f} | {' | '.join(compared)} | {row['inside']} | {row['crossing']} | "
            f"{1e3 * row.get('largest_jump_m', 0.0):.1f} | {1e3 * row.get('jump_bound_m', 0.0):.1f} | "
            f"{row.get('particles_beyond', 0)} |")
    later = [row["seconds"] for row in frames[1:]]
    cold = [row["cold_seconds"] for row in frames if "cold_seconds" in row]
    to_cold = [row["mean_to_cold_m"] for row in frames if "mean_to_cold_m" in row]
    pops = sum(row.get("particles_beyond", 0) > 0 for row in frames)
    lines.append(f"later frames: median {statistics.median(later):.2f} s (p90 {np.quantile(later, 0.9):.2f}); cold "
                 f"retargets: median {statistics.median(cold):.2f} s; ratio {statistics.median(later) / statistics.median(cold):.2f}; "
                 f"mean distance to cold at most {1e3 * max(to_cold):.3f} mm; inside at most "
                 f"{max(row['inside'] for row in frames)}; frames that pop {pops}")
    lines.extend(stage_table(frames))
    own = [row for row in frames if "warm_to_own_m" in row]
    if own:
        lines.append("against a retarget onto the sweep's own mesh (no wrap), mean mm, warm (wrap carried) / cold "
                     "(its own wrap): " + ", ".join(f"frame {row['frame']} {1e3 * row['warm_to_own_m']:.3f} / "
                                                    f"{1e3 * row['cold_to_own_m']:.3f}" for row in own))
    if result.get("tight"):
        lines.append(f"last frame against a cold retarget at {TIGHT_FACTOR:g}x the tolerances: the default cold "
                     f"{1e3 * result['tight']['cold_to_tight_m']:.3f} mm, the warm frame "
                     f"{1e3 * result['tight']['warm_to_tight_m']:.3f} mm (mean); Eq. 1 per particle: warm "
                     "{:.5f}, cold {:.5f}, tight {:.5f}".format(*result["tight"]["energies"]))
    return "\n".join(lines)


def stage_table(frames: list[dict]) -> list[str]:
    """Where the time goes: each stage's median seconds over the later frames and over the cold retargets."""
    later = [row["stages"] for row in frames[1:]]
    cold = [row["cold_stages"] for row in frames if "cold_stages" in row]
    if not later or not cold:
        return []
    lines = ["| stage | later frames, median s | cold retargets, median s |", "|---|---|---|"]
    for stage in (*STAGES, "segment_rounds"):
        warm_median, cold_median = (statistics.median(row[stage] for row in rows) for rows in (later, cold))
        if warm_median or cold_median:
            name = "(of the two levels) segment rounds" if stage == "segment_rounds" else stage
            lines.append(f"| {name} | {warm_median:.3f} | {cold_median:.3f} |")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sizes", nargs="+", type=float, default=[1e5, 1e6])
    parser.add_argument("--steps", type=int, default=24)
    parser.add_argument("--cold-every", type=int, default=4)
    parser.add_argument("--temporal", type=float, default=0.0)
    parser.add_argument("--tight", action="store_true", help="also retarget the last frame cold at tighter tolerances")
    parser.add_argument("--spacing", type=float, default=None, help="the spacing term's weight, warm and cold alike "
                                                                     "(default: a sequence's)")
    parser.add_argument("--remesh", type=int, help="the sweep on another mesh of about this many vertices (wrapped)")
    parser.add_argument("--one", type=float, help=argparse.SUPPRESS)  # the child: one size, JSON out
    args = parser.parse_args(argv)
    if args.spacing is None:
        from hairport.solver.options import SEQUENCE_SPACING

        args.spacing = SEQUENCE_SPACING
    if args.one is not None:
        print(json.dumps(measure(int(args.one), args.steps, args.cold_every, args.temporal, args.tight, args.spacing,
                                 args.remesh)))
        return 0
    print(f"# {_machine()}; temporal {args.temporal:g}, spacing {args.spacing:g}")
    for size in args.sizes:
        child = subprocess.run([sys.executable, __file__, "--one", str(size), "--steps", str(args.steps),
                                "--cold-every", str(args.cold_every), "--temporal", str(args.temporal),
                                "--spacing", str(args.spacing), *(["--tight"] if args.tight else []),
                                *(["--remesh", str(args.remesh)] if args.remesh else [])],
                               check=True, capture_output=True, text=True)
        print(table(json.loads(child.stdout.strip().splitlines()[-1])), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
