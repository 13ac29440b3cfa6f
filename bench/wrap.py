"""Benchmark of the wrap (solver/wrap/): seconds, peak memory, residual and accuracy per target size.

The source is MakeHuman ``average-female`` (13,380 vertices); the targets are the other presets
remeshed (:func:`hairport.solver.synthetic.remesh.remesh`, isotropic) to about 5k, 20k and 100k
vertices: whole bodies, heads cut at the neck (remeshed after the cut, so that a "20k head" has
20k vertices) and busts cut at the chest. The fitted region is the hair's: the source vertices
within :data:`REACH_M` of a procedural ``long`` groom (:func:`hairport.solver.wrap.hair_region`).

Per target the table prints the median wall time of ``--runs`` wraps (target preparation
included: the closest-point tree, the head frame) and their process CPU time (all threads:
on 2 cores shared with other work the wall time grows, the CPU time much less), the peak of memory traced by ``tracemalloc``
in one more run (numpy's arrays; the factorisation library's own buffers are not traced, their
size is printed as ``factor MB`` from the factor's entries where the library tells), the
wrap's residual (symmetric surface distance over the fitted region, mean / p95 / max mm) and
the truth: the original preset has the source's topology, so wrapped vertex ``i`` should land
on preset vertex ``i``; ``scalp`` is the mean / p95 of ``|wrapped - truth|`` (mm) over the
scalp's vertices, ``head+neck`` over the head- and neck-dominant ones (mean / p95 / max).

    python bench/wrap.py [--runs 3] [--sizes 5000 20000 100000] [--kinds body head bust]
                         [--presets heavy-male child ...] [--refusal] [--factor]

``--refusal`` prints the residual of bad targets (spheres, a box, tori) and good ones, the
measurements behind the limits of :mod:`hairport.solver.wrap.result`; ``--factor`` times the
factorisation libraries on the fitting matrix (:mod:`hairport.solver.wrap.factor`; qdldl and
cholespy only when installed: they are not dependencies).
"""

from __future__ import annotations

import argparse
import functools
import statistics
import time
import tracemalloc

import numpy as np

from hairport.solver.body.head_frame import head_frame
from hairport.solver.synthetic.groom import generate_groom, scalp_faces
from hairport.solver.synthetic.makehuman import PRESETS, build_character
from hairport.solver.synthetic.remesh import bust_cut, head_cut, remesh
from hairport.solver.wrap import WrapOptions, hair_region, wrap_body

SOURCE = "average-female"
#: the hair region: source vertices within this distance (m) of a hair particle
REACH_M = 0.05
#: the groom that defines the region: strands x particles per strand
GROOM = (2000, 30)
#: a vertex is neck-dominant above this skin weight of ``neck_01``
NECK_WEIGHT = 0.5


@functools.lru_cache(maxsize=None)
def source():
    """(character, hair region, scalp vertex ids, head+neck mask)."""
    character = build_character(PRESETS[SOURCE])
    frame = head_frame(character)
    hair = generate_groom(character, "long", *GROOM, seed=0)
    region = hair_region(character.vertices, character.faces, hair.points, REACH_M)
    scalp = np.unique(character.faces[scalp_faces(character, frame)])
    neck = np.asarray(character.weights[:, character.skeleton.index("neck_01")].todense()).ravel() > NECK_WEIGHT
    return character, region, scalp, frame.head_vertices | neck


@functools.lru_cache(maxsize=None)
def target(preset: str, kind: str, size: int):
    """(vertices, faces, truth vertices) of a remeshed target: a body, a head or a bust of ~``size`` vertices."""
    truth = build_character(PRESETS[preset])
    if kind == "head":
        truth_part = head_cut(truth)[0]
    elif kind == "bust":
        truth_part = bust_cut(truth)[0]
    else:
        truth_part = truth
    vertices, faces = remesh(truth_part.vertices, truth_part.faces, size, seed=1)
    return vertices, faces, truth.vertices


def errors(wrapped: np.ndarray, truth: np.ndarray, ids) -> np.ndarray:
    """(k,) mm: ``|wrapped - truth|`` over some vertices."""
    return np.linalg.norm(wrapped[ids] - truth[ids], axis=1) * 1e3


def measure(preset: str, kind: str, size: int, runs: int, options: WrapOptions) -> dict:
    character, region, scalp, head_neck = source()
    vertices, faces, truth = target(preset, kind, size)
    seconds, cpu = [], []
    for _ in range(runs):
        began = time.process_time()
        result = wrap_body(character.vertices, character.faces, vertices, faces, region, None, options)
        seconds.append(result.seconds)
        cpu.append(time.process_time() - began)
    tracemalloc.start()
    wrap_body(character.vertices, character.faces, vertices, faces, region, None, options)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return {"result": result, "seconds": statistics.median(seconds), "cpu": statistics.median(cpu), "peak": peak,
            "n": len(vertices),
            "scalp": errors(result.vertices, truth, scalp), "head_neck": errors(result.vertices, truth, head_neck)}


def table(presets, kinds, sizes, runs):
    character, region, _, _ = source()
    print(f"source {SOURCE}: {character.n_vertices} vertices; hair region {region.sum()} vertices "
          f"(within {REACH_M * 100:.0f} cm of a long groom of {GROOM[0]}x{GROOM[1]}); median of {runs} runs\n")
    header = (f"{'target':<18}{'kind':<6}{'V':>8}{'wrap s':>8}{'cpu s':>7}{'peak MB':>9}{'iters':>7}{'factors':>8}"
              f"{'residual mm':>20}{'scalp mm':>14}{'head+neck mm':>20}")
    print(header)
    print("-" * len(header))
    options = WrapOptions(refuse=False)
    for kind in kinds:
        for size in sizes:
            for preset in presets:
                row = measure(preset, kind, size, runs, options)
                r, s, h = row["result"].residual.symmetric, row["scalp"], row["head_neck"]
                print(f"{preset:<18}{kind:<6}{row['n']:>8,}{row['seconds']:>8.2f}{row['cpu']:>7.2f}"
                      f"{row['peak'] / 2**20:>9.0f}"
                      f"{row['result'].iterations:>7}{row['result'].factorisations:>8}"
                      f"{r.mean * 1e3:>8.2f}/{r.p95 * 1e3:.2f}/{r.max * 1e3:<6.1f}"
                      f"{s.mean():>7.2f}/{np.percentile(s, 95):<6.2f}"
                      f"{h.mean():>8.2f}/{np.percentile(h, 95):.2f}/{h.max():.1f}", flush=True)


def refusal():
    """Residuals of bad targets (refused) and good ones: the limits of solver/wrap/result.py."""
    import trimesh

    character, region, _, head_neck = source()
    centre = np.array([0.0, 0.72, 0.0])  # where the source's head is; the start finds it anyway
    shapes = {"sphere r10": trimesh.creation.icosphere(5, 0.1), "sphere r20": trimesh.creation.icosphere(5, 0.2),
              "box 20x25x22": trimesh.creation.box((0.2, 0.25, 0.22)),
              "torus 10/4": trimesh.creation.torus(0.1, 0.04, 64, 32),
              "torus 30/10": trimesh.creation.torus(0.3, 0.1, 64, 32)}
    cases = [(name, mesh.vertices + centre, np.asarray(mesh.faces)) for name, mesh in shapes.items()]
    cases += [(f"{preset} {kind} {size}", *target(preset, kind, size)[:2]) for preset in PRESETS if preset != SOURCE
              for kind in ("body", "head", "bust") for size in (5000, 20000)]
    print(f"{'target':<28}{'region':<10}{'mean mm':>9}{'p95 mm':>9}{'max mm':>9}{'coverage':>10}{'agreement':>11}  refused")
    for name, vertices, faces in cases:
        for label, mask in (("hair", region), ("head+neck", head_neck)):
            result = wrap_body(character.vertices, character.faces, vertices, faces, mask, None,
                               WrapOptions(refuse=False))
            r = result.residual
            refused = _refused(result)
            print(f"{name:<28}{label:<10}{r.symmetric.mean * 1e3:>9.2f}{r.symmetric.p95 * 1e3:>9.2f}"
                  f"{r.symmetric.max * 1e3:>9.1f}{r.coverage:>10.2f}{r.agreement:>11.3f}  {refused}", flush=True)


def _refused(result) -> str:
    from hairport.solver.model.errors import InputError
    from hairport.solver.wrap import check_wrap

    try:
        check_wrap(result)
    except InputError:
        return "yes"
    return "no"


def factor_libraries():
    """Seconds to factor the fitting matrix of the MakeHuman head, its whole body and the toy body,
    with SuperLU's orderings and, when installed, qdldl and CHOLMOD (cholespy): the table of
    solver/wrap/factor.py."""
    import importlib.util

    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from hairport.solver.synthetic.toy import toy_character
    from hairport.solver.wrap.region import region_mesh
    from hairport.solver.wrap.system import AmbergSystem

    character = source()[0]
    toy = toy_character()
    methods = {
        "splu MMD(A+A^T) symmetric": lambda a: spla.splu(a, permc_spec="MMD_AT_PLUS_A",
                                                        options={"SymmetricMode": True}),
        "splu COLAMD": lambda a: spla.splu(a, permc_spec="COLAMD"),
    }
    if importlib.util.find_spec("qdldl"):
        import qdldl

        methods["qdldl"] = lambda a: qdldl.Solver(sp.triu(a, format="csc"), upper=True)
    if importlib.util.find_spec("cholespy"):
        from cholespy import CholeskySolverD, MatrixType

        def cholmod(a):
            c = a.tocoo()
            return CholeskySolverD(a.shape[0], c.row.astype(np.int32), c.col.astype(np.int32), c.data, MatrixType.COO)

        methods["CHOLMOD (cholespy)"] = cholmod
    meshes = (("MakeHuman head", character, head_frame(character).head_vertices),
              ("MakeHuman body", character, np.ones(character.n_vertices, bool)),
              ("toy body", toy, np.ones(toy.n_vertices, bool)))
    for label, mesh, mask in meshes:
        ids, _, edges = region_mesh(mesh.faces, mask)
        points = mesh.vertices[ids] - mesh.vertices[ids].mean(axis=0)
        system = AmbergSystem(points / np.sqrt((points ** 2).sum(axis=1).mean()), edges, 1.0)
        matrix = system.matrix(1.0, (np.arange(len(ids)) % 10 != 0).astype(float))
        times = {}
        for name, method in methods.items():
            began = time.perf_counter()
            method(matrix)
            times[name] = time.perf_counter() - began
        print(f"{label}: {matrix.shape[0]:,} unknowns, {matrix.nnz:,} entries: "
              + ", ".join(f"{k} {v:.3f} s" for k, v in times.items()))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--sizes", type=int, nargs="*", default=[5000, 20000, 100000])
    parser.add_argument("--kinds", nargs="*", default=["head", "body", "bust"])
    parser.add_argument("--presets", nargs="*", default=[p for p in PRESETS if p != SOURCE])
    parser.add_argument("--refusal", action="store_true", help="the refusal limits' measurements")
    parser.add_argument("--factor", action="store_true", help="the factorisation libraries")
    args = parser.parse_args()
    if args.factor:
        factor_libraries()
    elif args.refusal:
        refusal()
    else:
        table(args.presets, args.kinds, args.sizes, args.runs)


if __name__ == "__main__":
    main()
