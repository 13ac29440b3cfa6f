"""The multi-scale solve's coarse level (the guides, coupled) alone: its linear-solve paths side by side.

Builds Table 4's groom (average female -> heavy male, 'long'; bench/table4.py) at one size,
runs the initial transfer, then solves the coarse level as
:func:`solver.adaptation.multiscale.solve_multiscale` poses it, once per path of
:func:`.contact_qp.solve_qp`'s coupled rounds, all in this process (the kernels warmed up
first), ``--runs`` times each, interleaved:

* ``before``: the numpy reference (scipy banded Cholesky, sparse products), every round's
  conjugate gradients from zero to :data:`.contact_qp.CG_RELATIVE_TOLERANCE` (the path
  before issue 13);
* ``compiled``: the same rounds by the compiled kernels (:mod:`.coupled_kernels`);
* ``+warm``: ... each round's CG started from the previous round's solution;
* ``after``: ... and rounds whose active set still changes solved to
  :data:`.contact_qp.SCREENING_CG_TOLERANCE` only, with the cycle guard (the default).

It prints, per path, the median wall-clock and CPU seconds of this process (less sensitive
to other jobs on a shared machine) and their ratios to ``before``, outer iterations,
active-set rounds, CG steps, whether it converged, the final merit, and the largest and mean
distance of its guides from the ``before`` result. With ``--compare N`` the first N QPs are
solved again by conjugate gradients and by the sparse direct factorisation
(:data:`.contact_qp.DIRECT_SOLVE_MAX_PARTICLES`), each timed, with the largest difference
of their steps.

    python bench/coarse_stage.py [--size 1e5] [--guides 300] [--runs 3] [--paths before after] [--compare 3]

Prints figures; not a test. Times are wall-clock seconds on this machine.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np
from table4 import SOURCE, STYLE, TARGET, groom_shape

#: solve_qp's keywords per path, in the order they run
PATHS = {
    "before": {"linear_solver": "numpy", "warm_start": False, "screening": False},
    "compiled": {"linear_solver": "compiled", "warm_start": False, "screening": False},
    "+warm": {"linear_solver": "compiled", "warm_start": True, "screening": False},
    "after": {"linear_solver": "compiled", "warm_start": True, "screening": True},
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="1e5", help="particles of the groom")
    parser.add_argument("--guides", type=int, default=300)
    parser.add_argument("--runs", type=int, default=3, help="solves per path (median)")
    parser.add_argument("--paths", nargs="+", default=list(PATHS), choices=list(PATHS))
    parser.add_argument("--compare", type=int, default=0, help="QPs to solve again by CG and by direct factorisation")
    args = parser.parse_args()

    from hairport import solver
    from hairport.solver import kernels
    from hairport.solver.adaptation.coupled import contact_qp, numpy_level
    from hairport.solver.adaptation.loop.options import SolveOptions
    from hairport.solver.adaptation.multiscale import CONTACT_BAND
    from hairport.solver.adaptation.solve import solve_hairstyle
    from hairport.solver.body.target import prepare_target
    from hairport.solver.mesh.collision import collision_query
    from hairport.solver.mesh.distance_grid import DistanceGrid
    from hairport.solver.model.hair import particle_indices
    from hairport.solver.pipeline import GRID_REGION_MARGIN, initial_transfer
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import PRESETS, build_character

    strands, per_strand = groom_shape(int(float(args.size)))
    source, target = build_character(PRESETS[SOURCE]), build_character(PRESETS[TARGET])
    hair = generate_groom(source, STYLE, strands, per_strand, seed=0)
    adaptable = solver.preprocess(source, hair, solver.PreprocessOptions(guides=args.guides))
    options = solver.RetargetOptions(method="multiscale")
    target = prepare_target(adaptable, target)
    body = collision_query(target.vertices, target.faces, target.name)
    initial, _ = initial_transfer(adaptable, target, options.eps_s, carry=options.carry)
    grid = DistanceGrid.build(body, region=(initial.min(axis=0) - GRID_REGION_MARGIN,
                                            initial.max(axis=0) + GRID_REGION_MARGIN))
    solve_options = SolveOptions(eps_c=options.eps_c, max_iterations=options.max_iterations,
                                 step_tolerance=options.step_tolerance, energy_tolerance=options.energy_tolerance)
    kernels.warm_up()

    # the guides' problem exactly as solve_multiscale poses it
    model = adaptable.multiscale
    guide_particles = particle_indices(hair.offsets, model.guides)
    counts = hair.counts[model.guides]
    guide_offsets = np.concatenate([[0], np.cumsum(counts)])
    guide_roots = np.zeros(len(guide_particles), dtype=bool)
    guide_roots[guide_offsets[:-1]] = True

    solve_qp = contact_qp.solve_qp
    qps = []

    def solve(path: str, record: bool = False):
        def patched(*qp, **keywords):
            if record and len(qps) < args.compare:
                qps.append(qp)
            return solve_qp(*qp, **{**keywords, **PATHS[path]})

        numpy_level.solve_qp = patched
        try:
            began, began_cpu = time.perf_counter(), time.process_time()
            points, report = solve_hairstyle(
                adaptable.coarse_model, guide_offsets, initial[guide_particles], guide_roots, body,
                options.energy_weights(), solve_options, grid=grid, band=CONTACT_BAND,
            )
            return points, report, time.perf_counter() - began, time.process_time() - began_cpu
        finally:
            numpy_level.solve_qp = solve_qp

    seconds = {path: [] for path in args.paths}
    cpu_seconds = {path: [] for path in args.paths}
    results = {}
    for run in range(args.runs):
        for path in args.paths:
            points, report, elapsed, cpu = solve(path, record=run == 0 and path == args.paths[0])
            seconds[path].append(elapsed)
            cpu_seconds[path].append(cpu)
            results[path] = points, report

    print(f"{hair.n_particles} particles, {len(model.guides)} guides ({len(guide_particles)} particles), "
          f"coarse level, median of {args.runs} runs")
    reference = results[args.paths[0]][0]
    print(f"{'path':<10} {'seconds':>8} {'ratio':>6} {'cpu s':>7} {'ratio':>6} {'iter':>5} {'rounds':>7} "
          f"{'CG steps':>9} {'conv':>5} {'merit':>10} {'max dist m':>11} {'mean dist m':>12}")
    first = statistics.median(seconds[args.paths[0]])
    first_cpu = statistics.median(cpu_seconds[args.paths[0]])
    for path in args.paths:
        points, report = results[path]
        median, cpu = statistics.median(seconds[path]), statistics.median(cpu_seconds[path])
        distance = np.linalg.norm(points - reference, axis=1)
        print(f"{path:<10} {median:8.2f} {median / first:6.2f} {cpu:7.2f} {cpu / first_cpu:6.2f} {report.iterations:5d} "
              f"{sum(report.active_set_rounds):7d} "
              f"{sum(report.cg_steps):9d} {str(report.converged):>5} {report.merit[-1]:10.3f} {distance.max():11.1e} "
              f"{distance.mean():12.1e}")

    for number, qp in enumerate(qps):
        began = time.perf_counter()
        cg = solve_qp(*qp, direct_max_particles=0)
        cg_seconds = time.perf_counter() - began
        began = time.perf_counter()
        direct = solve_qp(*qp, direct_max_particles=len(guide_particles))
        direct_seconds = time.perf_counter() - began
        print(f"  QP {number + 1}: CG {cg_seconds:.2f} s ({cg[3]} rounds, {cg[4]} steps), direct {direct_seconds:.2f} s "
              f"({direct[3]} rounds); steps differ by {np.abs(cg[0] - direct[0]).max():.1e} m "
              f"(largest {np.abs(direct[0]).max():.1e} m), active sets by {int(np.sum(cg[2] != direct[2]))}")


if __name__ == "__main__":
    main()
