"""The multi-scale solve's fine level (Eq. 14, every normal strand on its own): numpy reference vs compiled kernels.

Builds Table 4's groom (average female -> heavy male, 'long'; bench/table4.py) at one size,
runs the initial transfer and the coarse level once, then the fine level as
:func:`solver.adaptation.multiscale.solve_multiscale` calls it, by each engine
(:data:`solver.adaptation.loop.options.ENGINES`) in turn, ``--runs`` times in the same process,
and prints per engine the median wall-clock and CPU seconds (this process's threads and its
worker processes; on a shared machine the CPU time is the steadier figure), the outer
iterations (the longest chunk's), the microseconds per particle per iteration (seconds /
(particles x iterations)), the peak resident memory (this process's high-water mark during
the runs plus the largest worker's), the largest distance between the engines' results,
and the strands still open per iteration. ``--workers`` adds the compiled engine in that
many processes (the process pool).

    python bench/fine_stage.py [--size 1e5] [--guides 300] [--style long] [--runs 3] [--engines numpy compiled]
                               [--workers 2] [--chunk-particles 20000]

Prints figures; not a test. Times are wall-clock seconds on this machine.
"""

from __future__ import annotations

import argparse
import resource
import statistics
import time

import numpy as np
from table4 import SOURCE, STYLE, TARGET, _reset_peak, _status_bytes, groom_shape


def fine_level_case(size: int, guides: int, style: str = STYLE):
    """The fine level's inputs at ``size`` particles: (problem, start, body, grid, weights, options)."""
    from hairport import solver
    from hairport.solver.adaptation.loop.options import SolveOptions
    from hairport.solver.adaptation.multiscale import CONTACT_BAND, fine_problem
    from hairport.solver.adaptation.solve import solve_hairstyle
    from hairport.solver.body.target import prepare_target
    from hairport.solver.mesh.collision import collision_query
    from hairport.solver.mesh.distance_grid import DistanceGrid
    from hairport.solver.model.hair import particle_indices
    from hairport.solver.pipeline import GRID_REGION_MARGIN, initial_transfer
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import PRESETS, build_character

    strands, per_strand = groom_shape(size)
    source, target = build_character(PRESETS[SOURCE]), build_character(PRESETS[TARGET])
    hair = generate_groom(source, style, strands, per_strand, seed=0)
    adaptable = solver.preprocess(source, hair, solver.PreprocessOptions(guides=guides))
    options = solver.RetargetOptions(method="multiscale")
    weights = options.energy_weights()
    target = prepare_target(adaptable, target)
    body = collision_query(target.vertices, target.faces, target.name)
    initial, _ = initial_transfer(adaptable, target, options.eps_s, carry=options.carry)
    grid = DistanceGrid.build(body, region=(initial.min(axis=0) - GRID_REGION_MARGIN,
                                            initial.max(axis=0) + GRID_REGION_MARGIN))
    solve_options = SolveOptions(eps_c=options.eps_c, max_iterations=options.max_iterations,
                                 step_tolerance=options.step_tolerance, energy_tolerance=options.energy_tolerance)
    # the guides exactly as solve_multiscale solves them, then the fine problem it poses
    model = adaptable.multiscale
    guide_particles = particle_indices(hair.offsets, model.guides)
    guide_offsets = np.concatenate([[0], np.cumsum(hair.counts[model.guides])])
    guide_roots = np.zeros(len(guide_particles), dtype=bool)
    guide_roots[guide_offsets[:-1]] = True
    points = initial.copy()
    points[guide_particles], _ = solve_hairstyle(
        adaptable.coarse_model, guide_offsets, initial[guide_particles], guide_roots, body, weights, solve_options,
        grid=grid, band=CONTACT_BAND,
    )
    fine = adaptable.fine_source
    problem = fine_problem(hair, model, fine, points, initial, np.ones(hair.n_particles), spacing=bool(weights.spacing))
    return problem, initial[fine.particles], body, grid, weights, solve_options


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="1e5", help="particles of the groom")
    parser.add_argument("--guides", type=int, default=300)
    parser.add_argument("--style", default=STYLE, help="groom style (the fringe's strands converge slowest)")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--engines", nargs="+", default=["numpy", "compiled"])
    parser.add_argument("--workers", type=int, default=1, help="also run the compiled engine in this many processes")
    parser.add_argument("--chunk-particles", type=int, default=None, help="particles per chunk (the default's)")
    args = parser.parse_args()

    from hairport.solver.adaptation.multiscale import DEFAULT_CHUNK_PARTICLES, solve_fine_level
    from hairport.solver.kernels import threads, warm_up

    warm_up()
    problem, start, body, grid, weights, options = fine_level_case(int(float(args.size)), args.guides, args.style)
    n = problem.n_particles
    print(f"fine level: {n} particles, {problem.n_strands} strands, {threads()} numba threads, "
          f"median of {args.runs}")
    runs = [(engine, 1) for engine in args.engines]
    if args.workers > 1:
        runs.append(("compiled", args.workers))
    results = {}
    print(f"{'engine':<18}{'seconds':>9}{'cpu s':>8}{'iterations':>12}{'us/particle/it':>16}{'peak MB':>9}"
          f"{'converged':>11}")
    for engine, workers in runs:
        seconds, cpu = [], []
        peak = 0
        for _ in range(args.runs):
            fresh = _reset_peak()
            before = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
            began = time.perf_counter()
            points, reports, _ = solve_fine_level(problem, start, body, weights, options, grid, workers=workers,
                                                  chunk_particles=args.chunk_particles or DEFAULT_CHUNK_PARTICLES,
                                                  engine=engine)
            seconds.append(time.perf_counter() - began)
            after = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu.append(sum(b.ru_utime + b.ru_stime - a.ru_utime - a.ru_stime for a, b in zip(before, after)))
            # this process's high-water mark (reset before each run where the kernel lets us) plus the
            # largest worker process's
            peak = max(peak, (_status_bytes("VmHWM") if fresh else 0)
                       + (1024 * after[1].ru_maxrss if workers > 1 else 0))
        label = engine if workers == 1 else f"{engine} x{workers} proc"
        results[label] = (points, reports)
        median = statistics.median(seconds)
        iterations = max(r.iterations for r in reports)
        print(f"{label:<18}{median:>9.2f}{statistics.median(cpu):>8.2f}{iterations:>12}"
              f"{1e6 * median / (n * iterations):>16.3f}{peak / 1e6:>9.0f}{str(all(r.converged for r in reports)):>11}")
    labels = list(results)
    for label in labels[1:]:
        print(f"largest distance {labels[0]} vs {label}: "
              f"{np.abs(results[label][0] - results[labels[0]][0]).max():.1e} m")
    for label, (_, reports) in results.items():
        longest = max(reports, key=lambda r: r.iterations)
        print(f"{label}: strands open per iteration (largest chunk of {len(reports)}): {longest.open_groups}")


if __name__ == "__main__":
    main()
