"""Closest-face and ray backends behind :class:`.query.MeshQuery`: the compiled BVH (default), libigl AABB
(the reference), fcpw (opt-in), embree rays."""

from __future__ import annotations

from operator import attrgetter

import igl
import numpy as np

from hairport.solver.mesh import bvh
from hairport.solver.mesh.cells import DEFAULT_CELL_SIZE, CellCache
from hairport.solver.mesh.signed_distance import signed_distance

#: a tree refit to moved vertices (:meth:`_CompiledFaces.moved`) is built anew instead when its boxes' area grows
#: beyond this times its build's (:func:`.bvh.node_area`): measured on the MakeHuman body, refitting the average
#: female's tree to the heavy male's vertices (every vertex moved, up to ~15 cm) grows it 1.45 times, a fresh build
#: 1.34 times, and searches in the refit tree take 8 % longer; a refit takes ~10 ms, a build ~40 ms
REFIT_AREA_GROWTH = 1.5

#: face-search backends for :meth:`~hairport.solver.mesh.query.MeshQuery.signed_distance`, the first importable one is
#: used: the compiled BVH (float64, exact; 2x libigl's AABB on hair near the body, 4x with a cell cache, see
#: ``bench/closest_point.py``), libigl's AABB (the tested reference), ``("fcpw", "igl")`` opts in to fcpw (float32)
CLOSEST_FACE_BACKENDS = ("bvh", "igl")


_PRIMITIVE_INDEX = attrgetter("primitive_index")

#: |cos| between a ray and the normal of its hit face at or below which the hit is dropped as
#: grazing (trimesh's ``planes_lines`` tolerance, which the previous implementation applied)
_PARALLEL = 1e-5


class _FcpwFaces:
    """Closest face by fcpw's vectorised BVH (float32; coordinates centred first)."""

    exact = False

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        import fcpw

        self._fcpw = fcpw
        lo, hi = vertices.min(axis=0), vertices.max(axis=0)
        self._center = 0.5 * (lo + hi)
        scene = fcpw.scene_3D()
        scene.set_object_count(1)
        scene.set_object_vertices(np.asfortranarray(vertices - self._center, dtype=np.float32), 0)
        scene.set_object_triangles(np.asfortranarray(faces, dtype=np.int32), 0)
        scene.build(fcpw.aggregate_type.bvh_surface_area, True, False, False)
        self._scene = scene

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, None]:
        """Face holding the closest point (no closest point: float32 would not do)."""
        n = len(points)
        interactions = self._fcpw.interaction_3D_list()
        self._scene.find_closest_points(
            np.asfortranarray(points - self._center, dtype=np.float32),
            np.full(n, np.inf, dtype=np.float32),
            interactions,
            False,
        )
        faces = np.fromiter(map(_PRIMITIVE_INDEX, interactions), dtype=np.int64, count=n)
        return np.maximum(faces, 0), None  # -1 only for non-finite points, whose results are NaN anyway


class _EmbreeFaces:
    """First face hit by each ray, by Embree (float32; coordinates centred first)."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        self._center = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
        self._scene = rtcore_scene.EmbreeScene()
        TriangleMesh(scene=self._scene, vertices=(vertices - self._center).astype(np.float32), indices=faces.astype(np.int32))

    def first_faces(self, origins: np.ndarray, unit: np.ndarray) -> np.ndarray:
        """(N,) int64 face index, ``-1`` where the ray misses."""
        first = self._scene.run((origins - self._center).astype(np.float32), unit.astype(np.float32))
        return np.asarray(first, dtype=np.int64)


class _IglFaces:
    """Closest face by libigl's AABB tree (float64)."""

    exact = True

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        self._vertices, self._faces = vertices, faces
        self._tree = igl.AABB()
        self._tree.init(vertices, faces)

    def closest(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Face holding the closest point, and the closest point (face 0 and NaN for a
        non-finite point, for which libigl's face would be undefined)."""
        finite = np.isfinite(points).all(axis=1)
        if finite.all():
            _, faces, closest = self._tree.squared_distance(self._vertices, self._faces, points)
            return np.maximum(faces.astype(np.int64), 0), closest
        faces, closest = np.zeros(len(points), dtype=np.int64), np.full(points.shape, np.nan)
        if finite.any():
            faces[finite], closest[finite] = self.closest(np.ascontiguousarray(points[finite]))
        return faces, closest


class _CompiledFaces:
    """Closest face, point and signed distance by the compiled BVH (:mod:`.bvh`, float64), in
    one pass per point (:mod:`.signed_distance`); hints and cell caches (:mod:`.cells`) speed it up."""

    exact = True
    #: :meth:`signed` gives the whole signed distance (the query skips its numpy steps)
    fused = True

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, tree: bvh.TriangleTree | None = None):
        self._tree = bvh.build_tree(vertices, faces) if tree is None else tree

    def moved(self, vertices: np.ndarray, faces: np.ndarray) -> "_CompiledFaces":
        """The search over the same ``faces`` at moved ``vertices``: this tree refit, or built anew when the refit's
        boxes grew past :data:`REFIT_AREA_GROWTH` times its build's."""
        refit = bvh.refit_tree(self._tree, vertices, faces)
        if bvh.node_area(refit.boxes) > REFIT_AREA_GROWTH * self._tree.built_area:
            return _CompiledFaces(vertices, faces)
        return _CompiledFaces(vertices, faces, refit)

    def closest(self, points: np.ndarray, hint: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Face holding the closest point, and the closest point."""
        faces, closest, _, _ = bvh.closest_points(self._tree, points, hint)
        return np.maximum(faces, 0), closest

    def signed(self, points: np.ndarray, pseudonormals: np.ndarray, hint: np.ndarray | None = None,
               cells: CellCache | None = None):
        """:func:`.signed_distance.signed_distance`: distance, closest, normal, faces, feature."""
        return signed_distance(self._tree, pseudonormals, points, hint, cells)

    def cell_cache(self, size: float = DEFAULT_CELL_SIZE) -> CellCache:
        """An empty cell cache over this tree."""
        return CellCache(self._tree, size)


_FACE_INDEXES = {"bvh": _CompiledFaces, "fcpw": _FcpwFaces, "igl": _IglFaces}


def _closest_face_index(vertices: np.ndarray, faces: np.ndarray, backends=None):
    for name in backends or CLOSEST_FACE_BACKENDS:
        try:
            return _FACE_INDEXES[name](vertices, faces)
        except ImportError:
            continue
    raise ImportError(f"no closest-point backend available among {backends or CLOSEST_FACE_BACKENDS}")
