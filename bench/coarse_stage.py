"""The multi-scale solve's coarse level (the guides, coupled) alone, and its linear solves by CG or direct.

Builds Table 4's groom (average female -> heavy male, 'long'; bench/table4.py) at one size,
runs the initial transfer, then the coarse level as :func:`solver.adaptation.multiscale.solve_multiscale`
calls it, and prints its seconds, outer iterations, active-set rounds and CG steps. With
``--compare N`` the first N of its QPs are solved again by conjugate gradients and by the
sparse direct factorisation (:data:`.active_set.DIRECT_SOLVE_MAX_PARTICLES`), each timed,
with the largest difference of their steps.

    python bench/coarse_stage.py [--size 1e5] [--guides 300] [--compare 3]

Prints figures; not a test. Times are wall-clock seconds on this machine.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from table4 import SOURCE, STYLE, TARGET, groom_shape


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="1e5", help="particles of the groom")
    parser.add_argument("--guides", type=int, default=300)
    parser.add_argument("--compare", type=int, default=0, help="QPs to solve again by CG and by direct factorisation")
    args = parser.parse_args()

    from hairport import solver
    from hairport.solver.adaptation import active_set
    from hairport.solver.adaptation.coupled import solve_hairstyle
    from hairport.solver.adaptation.energies import EnergyWeights
    from hairport.solver.adaptation.multiscale import CONTACT_BAND
    from hairport.solver.adaptation.options import SolveOptions
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
    initial, _ = initial_transfer(adaptable, target, options.eps_s)
    grid = DistanceGrid.build(body, region=(initial.min(axis=0) - GRID_REGION_MARGIN,
                                            initial.max(axis=0) + GRID_REGION_MARGIN))
    solve_options = SolveOptions(eps_c=options.eps_c, max_iterations=options.max_iterations,
                                 step_tolerance=options.step_tolerance, energy_tolerance=options.energy_tolerance)

    # the guides' problem exactly as solve_multiscale poses it
    model = adaptable.multiscale
    guide_particles = particle_indices(hair.offsets, model.guides)
    counts = hair.counts[model.guides]
    guide_offsets = np.concatenate([[0], np.cumsum(counts)])
    guide_roots = np.zeros(len(guide_particles), dtype=bool)
    guide_roots[guide_offsets[:-1]] = True

    qps = []
    solve_qp = active_set.solve_qp

    def recording(*qp):  # keeps the first QPs' inputs for --compare
        if len(qps) < args.compare:
            qps.append(qp)
        return solve_qp(*qp)

    active_set.solve_qp = recording
    began = time.perf_counter()
    _, report = solve_hairstyle(
        adaptable.coarse_model, guide_offsets, initial[guide_particles], guide_roots, body,
        EnergyWeights(options.alpha, options.beta), solve_options, grid=grid, band=CONTACT_BAND,
    )
    seconds = time.perf_counter() - began
    active_set.solve_qp = solve_qp
    print(f"{hair.n_particles} particles, {len(model.guides)} guides ({len(guide_particles)} particles): coarse level "
          f"{seconds:.2f} s, {report.iterations} iterations, {sum(report.active_set_rounds)} active-set rounds, "
          f"{sum(report.cg_steps)} CG steps, converged {report.converged}")
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
