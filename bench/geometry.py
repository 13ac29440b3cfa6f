"""Benchmark of the geometric queries in solver/mesh/.

Prints, for random points near a ~27k-face body (the MakeHuman "average-female" preset when
it can be built, else a 20k-face icosphere), the median over runs of:

* signed distance (points jittered 1 cm around the surface; and hair-like strands, 100
  particles each, reaching 30 cm out): the previous implementation (``igl.signed_distance``
  per call, which rebuilds libigl's tree and normals every time) and :class:`MeshQuery`
  with each available face-search backend (libigl, the default; fcpw if installed), with
  and without sorting the queries along a Z-curve first;
* first ray hits (Embree through embreex) for random rays from around the body: the
  previous implementation (trimesh's ``intersects_location``) and the current one.

The ratio column is old time / new time in the same run (larger is better). Times are
wall-clock medians; the CPU column is process time, steadier on a shared machine.

    python bench/geometry.py [--runs 5] [--sizes 1000 10000 100000 1000000] [--strands 1000000] [--rays 100000 1000000]
"""

from __future__ import annotations

import argparse
import statistics
import time

import igl
import numpy as np

from hairport.solver.mesh import backends
from hairport.solver.mesh import query as mesh_query
from hairport.solver.mesh.query import MeshQuery


def load_body():
    try:
        from hairport.solver.synthetic.makehuman import build_preset

        body = build_preset("average-female")
        return "MakeHuman average-female", np.asarray(body.vertices, float), np.asarray(body.faces, np.int64)
    except Exception as error:  # no asset cache: a sphere of the same size
        import trimesh

        print(f"(MakeHuman preset unavailable: {error!r}; using an icosphere)")
        mesh = trimesh.creation.icosphere(subdivisions=5, radius=0.3)  # 20,480 faces
        return "icosphere", np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)


def points_near(vertices, n, rng, spread=0.01):
    """Surface vertices jittered by a normal of ``spread`` m: inside and outside, mostly close."""
    return vertices[rng.integers(0, len(vertices), n)] + rng.normal(scale=spread, size=(n, 3))


def strand_points(vertices, n, rng, per_strand=100):
    """Hair-like queries: strands of ``per_strand`` particles leaving random vertices, 3 mm
    apart with a random walk, in strand order (farther from the body, already coherent)."""
    m = n // per_strand
    roots = vertices[rng.integers(0, len(vertices), m)]
    heading = rng.normal(size=(m, 3))
    heading /= np.linalg.norm(heading, axis=1, keepdims=True)
    steps = heading[:, None] * 0.003 + rng.normal(scale=0.001, size=(m, per_strand, 3))
    return (roots[:, None] + np.cumsum(steps, axis=1)).reshape(-1, 3)


def timed(fn, runs, warm_up=True):
    """Median wall and CPU seconds of ``runs`` calls (after one warm-up call unless told not to)."""
    if warm_up:
        fn()  # lazy structures, caches
    walls, cpus = [], []
    for _ in range(runs):
        w, c = time.perf_counter(), time.process_time()
        fn()
        walls.append(time.perf_counter() - w)
        cpus.append(time.process_time() - c)
    return statistics.median(walls), statistics.median(cpus)


def forced(vertices, faces, backend):
    query = MeshQuery(vertices, faces)
    query._prepare()
    query._closest = backends._closest_face_index(query.vertices, query.faces, [backend])
    return query


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--sizes", type=int, nargs="+", default=[1_000, 10_000, 100_000, 1_000_000])
    parser.add_argument("--strands", type=int, nargs="*", default=[1_000_000])
    parser.add_argument("--rays", type=int, nargs="+", default=[100_000, 1_000_000])
    args = parser.parse_args()

    name, vertices, faces = load_body()
    print(f"mesh: {name}, {len(vertices)} vertices, {len(faces)} faces; median of {args.runs} runs\n")
    rng = np.random.default_rng(0)
    available = [b for b in backends._FACE_INDEXES if _available(b, vertices, faces)]

    # one-off setup
    for backend in available:
        w, c = timed(lambda: forced(vertices, faces, backend), args.runs)
        print(f"setup MeshQuery[{backend}] (tree + pseudonormal table): {w * 1e3:.1f} ms")
    print()

    queries = {f"MeshQuery[{b}]": forced(vertices, faces, b) for b in available}
    methods = {"old igl.signed_distance": lambda p: igl.signed_distance(p, vertices, faces, igl.SIGNED_DISTANCE_TYPE_PSEUDONORMAL)}
    methods.update({label: q.signed_distance for label, q in queries.items()})
    for label, q in queries.items():
        methods[f"{label}, no Z-sort"] = unsorted(q.signed_distance)

    header = f"{'signed distance':<34}{'N':>18}{'wall s':>10}{'cpu s':>10}{'old/new':>10}"
    print(header)
    print("-" * len(header))
    workloads = [(f"{n}", points_near(vertices, n, rng)) for n in args.sizes]
    workloads += [(f"{n} strands", strand_points(vertices, n, rng)) for n in args.strands]
    for n, points in workloads:
        base = None
        for label, fn in methods.items():
            wall, cpu = timed(lambda: fn(points), args.runs)
            base = wall if base is None else base
            print(f"{label:<34}{n:>18}{wall:>10.4f}{cpu:>10.4f}{base / wall:>10.1f}")
        if "MeshQuery[fcpw]" in queries:
            q = queries["MeshQuery[fcpw]"]
            share = (np.abs(q.signed_distance(points).distance) < q._exact_band).mean()
            print(f"{'  (fcpw: share re-searched in float64, near surface)':<54}{share:>10.1%}")
        print()

    header = f"{'first_hits (embree)':<34}{'N':>18}{'wall s':>10}{'cpu s':>10}{'old/new':>10}{'hit rate':>10}"
    print(header)
    print("-" * len(header))
    query = MeshQuery(vertices, faces)
    old = old_first_hits(vertices, faces)
    center = vertices.mean(axis=0)
    for n in args.rays:
        origins = points_near(vertices, n, rng, spread=0.05)
        directions = center + rng.normal(scale=0.1, size=(n, 3)) - origins
        rate = query.first_hits(origins, directions).hit.mean()
        base = None
        for label, fn in (("old trimesh intersects_location", old), ("MeshQuery.first_hits", query.first_hits)):
            wall, cpu = timed(lambda: fn(origins, directions), args.runs)
            base = wall if base is None else base
            print(f"{label:<34}{n:>18}{wall:>10.4f}{cpu:>10.4f}{base / wall:>10.1f}{rate:>10.1%}")


def old_first_hits(vertices, faces):
    """The previous first_hits: trimesh's embree intersector, locations, then barycentrics."""
    import trimesh
    from trimesh.ray.ray_pyembree import RayMeshIntersector

    from hairport.solver.mesh.triangles import barycentric_coordinates

    rays = RayMeshIntersector(trimesh.Trimesh(vertices, faces, process=False))

    def call(origins, directions):
        unit = directions / np.linalg.norm(directions, axis=1, keepdims=True)
        n = len(origins)
        hit, tri, points = np.zeros(n, bool), np.full(n, -1), np.zeros((n, 3))
        locations, ray_index, tri_index = rays.intersects_location(origins, unit, multiple_hits=False)
        hit[ray_index], tri[ray_index], points[ray_index] = True, tri_index, locations
        distance = np.where(hit, np.einsum("ij,ij->i", points - origins, unit), np.inf)
        barycentric = np.zeros((n, 3))
        barycentric[hit] = barycentric_coordinates(points[hit], vertices[faces[tri[hit]]])
        return hit, distance, tri, barycentric, points

    return call


def with_setting(name, value, fn):
    """``fn`` with ``mesh.query.<name>`` set to ``value`` during the call."""

    def call(points):
        keep = getattr(mesh_query, name)
        setattr(mesh_query, name, value)
        try:
            return fn(points)
        finally:
            setattr(mesh_query, name, keep)

    return call


def unsorted(fn):
    """``fn`` with the Morton ordering of the queries switched off."""
    return with_setting("SORT_QUERIES_FROM", np.iinfo(np.int64).max, fn)


def _available(backend, vertices, faces):
    try:
        backends._FACE_INDEXES[backend](vertices[:3], np.array([[0, 1, 2]]))
        return True
    except ImportError:
        return False


if __name__ == "__main__":
    main()
