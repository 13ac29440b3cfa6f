"""USD characters (``.usd``, ``.usda``, ``.usdc``): a ``UsdGeom.Mesh`` and its ``UsdSkel`` skin.

The mesh: the one named by ``mesh_name`` (prim name or path), else, like glTF, the skinned mesh
with the most vertices (any mesh when none is skinned); a tie is ``ambiguous_mesh``. Its faces
are triangulated as fans in file order (face ``v0 v1 ... vn`` gives ``(v0, vi, vi+1)``), so a
source and a target of one topology give the same triangles. Points are taken at the stage's
default time: a skinned mesh's through its ``primvars:skel:geomBindTransform`` into the
skeleton's space and the skeleton prim's world transform (its bind pose), an unskinned one's
through the mesh's world transform.

The skeleton: the ``UsdSkel.Skeleton`` bound to the mesh (``skel:skeleton``, inherited).
Bone ``b`` is joint ``b``, named after the last element of its path (made unique like
glTF's), its parent the joint whose path is its path's parent. Its head is the translation of
its ``bindTransforms`` matrix (world space of the skeleton, taken to the stage's world), its
tail as for a glTF skin (:func:`~hairport.solver.io.character.bones.bone_tails`). Weights come from
``primvars:skel:jointIndices``/``jointWeights`` (``elementSize`` influences a vertex, or
``constant`` for all), through the mesh's own ``skel:joints`` order when it has one.

A sequence's frames (:func:`read_usd_frames`): the mesh's time-sampled points, else its skeleton's
``UsdSkel.Animation`` evaluated by UsdSkel at each time code.

Units: the stage's ``metersPerUnit`` (one of hairport's units, else ``bad_header``). The up axis
is the input frame's to find (``--up-axis`` or inference), as for every format. Parsing runs in
a memory- and time-limited child (:mod:`~hairport.solver.io.sandbox`).

Other files: a stage naming any file (sublayer, reference, payload, clip, asset path) is refused
(``external_reference``) before anything is composed, unless ``allow_external_files``
(:mod:`~hairport.solver.io.usd.stage`).
"""

from __future__ import annotations

import os
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from hairport.solver.io.character.bones import bone_tails, unique_names
from hairport.solver.io.character.mesh_file import MAX_BONES, MeshFile, Skin, check_counts, fan_triangles
from hairport.solver.io.external import ALLOW_EXTERNAL_FILES
from hairport.solver.io.hair.common import ReadContext, ReadLimits
from hairport.solver.io.sandbox import run_in_child
from hairport.solver.io.usd.stage import open_stage, pxr_modules, stage_units, usd_reason
from hairport.solver.model.character import Skeleton, normalise_weight_rows


def read_usd(path: Path, *, max_vertices: int, max_faces: int, mesh_name: str | None,
             allow_external_files: bool = ALLOW_EXTERNAL_FILES) -> MeshFile:
    """The mesh (and skin) of a USD stage (module notes), parsed in a limited child; a stage naming
    another file is refused (``external_reference``) unless ``allow_external_files``."""
    source = str(path)
    arguments = {"name": path.name, "max_vertices": max_vertices, "max_faces": max_faces, "mesh_name": mesh_name,
                 "allow_external_files": allow_external_files}
    found = run_in_child(__name__, "mesh_arrays", source, os.path.getsize(source), arguments, source, "USD")
    skin = None
    if "bone_names" in found:
        skeleton = Skeleton(tuple(str(name) for name in found["bone_names"]), found["bone_parents"],
                            found["bone_heads"], found["bone_tails"])
        n_vertices, n_bones = len(found["vertices"]), len(found["bone_names"])
        weights = sp.csr_matrix((found["weight_values"], (found["weight_rows"], found["weight_columns"])),
                                shape=(n_vertices, n_bones))
        skin = Skin(skeleton, normalise_weight_rows(weights))
    return MeshFile(found["vertices"], found["faces"], skin, str(found["label"]), str(found["units"]))


def mesh_arrays(source: str, name: str, max_vertices: int, max_faces: int, mesh_name: str | None,
                allow_external_files: bool = ALLOW_EXTERNAL_FILES) -> dict[str, np.ndarray]:
    """In the child: the stage's mesh and skin as arrays (read back by :func:`read_usd`)."""
    with _chosen_mesh(source, name, mesh_name, allow_external_files) as (_, prim, units, ctx):
        return {"units": np.array(units), "label": np.array(str(prim.GetPath())),
                **_mesh(prim, ctx, max_vertices, max_faces)}


@contextmanager
def _chosen_mesh(source: str, name: str, mesh_name: str | None, allow_external_files: bool):
    """The stage, its chosen mesh prim, its units and the read context; a damaged value met on reading any of it is
    ``bad_header``."""
    _, _, _, _, Tf = pxr_modules()
    ctx = ReadContext(name, ReadLimits(), "m")
    stage = open_stage(source, ctx, allow_external_files)
    try:
        units = stage_units(stage, ctx)
        yield stage, _select_mesh(stage, mesh_name, ctx), units, ctx
    except Tf.ErrorException as error:
        raise ctx.error(f"damaged USD data: {usd_reason(error, ctx)}", "bad_header") from None


def read_usd_frames(path: Path, times: list[float], *, max_vertices: int, max_faces: int, mesh_name: str | None,
                    allow_external_files: bool = ALLOW_EXTERNAL_FILES) -> tuple[list[MeshFile], float]:
    """The mesh of a USD stage at each time code of ``times`` (an animated or swept body), parsed in a limited child,
    with no skin (a bind pose does not follow the points), and the stage's time codes per second.

    The mesh moves by its time-sampled points, or, when they have no samples and it is bound to a skeleton with a
    ``UsdSkel.Animation``, by that animation: its blend-shape weights and joint transforms, evaluated by UsdSkel
    (blend shapes, then linear blend skinning) into the skeleton's world space at each time.

    Raises
    ------
    InputError
        ``not_animated`` for a mesh whose points have fewer than two time samples and no skeleton animation of two,
        ``bad_frames`` for times outside its samples.
    """
    source = str(path)
    arguments = {"name": path.name, "times": [float(t) for t in times], "max_vertices": max_vertices,
                 "max_faces": max_faces, "mesh_name": mesh_name, "allow_external_files": allow_external_files}
    found = run_in_child(__name__, "mesh_frames", source, os.path.getsize(source), arguments, source, "USD")
    label, units = str(found["label"]), str(found["units"])
    frames = [MeshFile(points, found["faces"], None, f"{label}@{time:g}", units)
              for points, time in zip(found["frames"], times, strict=True)]
    return frames, float(found["frames_per_second"])


def mesh_frames(source: str, name: str, times: list[float], max_vertices: int, max_faces: int, mesh_name: str | None,
                allow_external_files: bool = ALLOW_EXTERNAL_FILES) -> dict[str, np.ndarray]:
    """In the child: the stage's mesh at each time code, in world space (read back by :func:`read_usd_frames`)."""
    Usd, UsdGeom, _, _, _ = pxr_modules()
    with _chosen_mesh(source, name, mesh_name, allow_external_files) as (stage, prim, units, ctx):
        where = str(prim.GetPath())
        samples = list(UsdGeom.Mesh(prim).GetPointsAttr().GetTimeSamples())
        pose = _skel_pose(prim) if len(samples) < 2 else None
        if pose is not None:
            samples = pose.times
        if len(samples) < 2:
            raise ctx.error(f"{where}: its points have {len(samples)} time sample{'s' if len(samples) != 1 else ''} "
                            "and no skeleton animation moves it, so it is not animated", "not_animated")
        if min(times) < samples[0] or max(times) > samples[-1]:
            raise ctx.error(f"{where}: frames {min(times):g} to {max(times):g} reach past its time samples "
                            f"({samples[0]:g} to {samples[-1]:g})", "bad_frames")
        first = _mesh(prim, ctx, max_vertices, max_faces, Usd.TimeCode(times[0]), skin=False)
        frames = np.empty((len(times), len(first["vertices"]), 3))
        frames[0] = first["vertices"] if pose is None else pose.world_points(Usd.TimeCode(times[0]), ctx)
        for number, time in enumerate(times[1:], start=1):  # the faces are frame 0's: only the points move
            vertices = (_world_points(prim, Usd.TimeCode(time)) if pose is None
                        else pose.world_points(Usd.TimeCode(time), ctx))
            if vertices.shape != frames[0].shape:
                raise ctx.error(f"{where}: at time {time:g} it has {len(vertices):,} points, at {times[0]:g} "
                                f"{len(frames[0]):,}: the frames of a sequence must be one mesh", "sequence_topology")
            frames[number] = vertices
        return {"units": np.array(units), "label": np.array(where), "faces": first["faces"], "frames": frames,
                "frames_per_second": np.array(stage.GetTimeCodesPerSecond())}


class _SkelPose:
    """A skinned mesh posed by its skeleton's ``UsdSkel.Animation`` (:meth:`world_points`); ``times`` are the
    animation's time samples (joint transforms and blend-shape weights together)."""

    def __init__(self, prim, cache, skeleton, skinning, animation, shapes) -> None:
        self.prim, self.cache, self.skeleton, self.skinning, self.animation = prim, cache, skeleton, skinning, animation
        self.shapes = shapes
        _, UsdGeom, _, _, _ = pxr_modules()
        attribute = UsdGeom.Mesh(prim).GetPointsAttr()
        self.rest = attribute.Get(still_time(attribute))  # copied for each pose: the queries deform it in place
        self.times = sorted(set(animation.GetJointTransformTimeSamples())
                            | set(animation.GetBlendShapeWeightTimeSamples()))
        if shapes is not None:
            self.shape_points, self.shape_offsets = (shapes.ComputeBlendShapePointIndices(),
                                                     shapes.ComputeSubShapePointOffsets())

    def world_points(self, time, ctx: ReadContext) -> np.ndarray:
        """``(P, 3)``: the rest points with the blend shapes at ``time``, skinned by the joints at ``time``, in the
        skeleton's world space."""
        _, UsdGeom, _, _, _ = pxr_modules()
        from pxr import Vt

        points = Vt.Vec3fArray(self.rest)
        where = str(self.prim.GetPath())
        if self.shapes is not None:
            weights = self.animation.ComputeBlendShapeWeights(time)
            mapper = self.skinning.GetBlendShapeMapper()
            if mapper is not None and not mapper.IsNull():
                weights = mapper.Remap(weights)
            if not self.shapes.ComputeDeformedPoints(*self.shapes.ComputeSubShapeWeights(weights), self.shape_points,
                                                     self.shape_offsets, points):
                raise ctx.error(f"{where}: its blend shapes do not fit its points", "bad_mesh")
        transforms = self.skeleton.ComputeSkinningTransforms(time)
        if transforms is None or not self.skinning.ComputeSkinnedPoints(transforms, points, time):
            raise ctx.error(f"{where}: it could not be skinned by its skeleton's animation", "bad_skeleton")
        world = _matrix(UsdGeom.Xformable(self.skeleton.GetPrim()).ComputeLocalToWorldTransform(time))
        return np.array(points, dtype=np.float64).reshape(-1, 3) @ world[:3, :3] + world[3, :3]


def _skel_pose(prim) -> _SkelPose | None:
    """The skeleton animation that poses a skinned mesh, or None (not skinned, no ``UsdSkel.Animation``)."""
    Usd, _, _, _, _ = pxr_modules()
    from pxr import UsdSkel

    if not _skinned(prim):
        return None
    root = UsdSkel.Root.Find(prim)
    if not root:
        return None
    cache = UsdSkel.Cache()
    cache.Populate(root, Usd.PrimDefaultPredicate)
    skinning = cache.GetSkinningQuery(prim)
    skeleton = cache.GetSkelQuery(UsdSkel.BindingAPI(prim).GetInheritedSkeleton()) if skinning else None
    animation = skeleton.GetAnimQuery() if skeleton else None
    if not animation:
        return None
    shapes = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(prim)) if skinning.HasBlendShapes() else None
    return _SkelPose(prim, cache, skeleton, skinning, animation, shapes)


def _skinned(prim) -> bool:
    from pxr import UsdSkel

    binding = UsdSkel.BindingAPI(prim)
    return bool(binding.GetJointIndicesPrimvar()) and binding.GetInheritedSkeleton().GetPrim().IsValid()


def _select_mesh(stage, mesh_name: str | None, ctx: ReadContext):
    _, UsdGeom, _, _, _ = pxr_modules()
    meshes = [prim for prim in stage.Traverse() if prim.IsA(UsdGeom.Mesh)]
    if not meshes:
        raise ctx.error("the stage has no Mesh prim", "empty_mesh")
    if mesh_name is not None:
        chosen = [prim for prim in meshes if mesh_name in (prim.GetName(), str(prim.GetPath()))]
        if not chosen:
            names = ", ".join(repr(str(prim.GetPath())) for prim in meshes)
            raise ctx.error(f"no mesh named {mesh_name!r}; the stage has {names}", "bad_mesh")
        return chosen[0]
    pool = [prim for prim in meshes if _skinned(prim)] or meshes
    sizes = [len(attribute.Get(still_time(attribute)) or [])
             for attribute in (UsdGeom.Mesh(prim).GetPointsAttr() for prim in pool)]
    best = [prim for prim, size in zip(pool, sizes, strict=True) if size == max(sizes)]
    if len(best) > 1:
        names = ", ".join(repr(str(prim.GetPath())) for prim in best)
        raise ctx.error(f"ambiguous: meshes {names} have {max(sizes)} vertices each; choose one with mesh_name",
                        "ambiguous_mesh")
    return best[0]


def _matrix(value) -> np.ndarray:
    return np.array(value, dtype=np.float64).reshape(4, 4)


def still_time(attribute):
    """The ``Usd.TimeCode`` a still read takes an attribute at: its default value, else (only time samples authored,
    as animated exports write them) its first sample."""
    Usd, _, _, _, _ = pxr_modules()
    if attribute.Get(Usd.TimeCode.Default()) is None and attribute.GetNumTimeSamples() > 0:
        return Usd.TimeCode.EarliestTime()
    return Usd.TimeCode.Default()


def _world_points(prim, time, points: np.ndarray | None = None) -> np.ndarray:
    """``(P, 3)``: a Mesh prim's points at ``time`` (a ``Usd.TimeCode``; or ``points`` already read at it) through its
    world transform at that time."""
    _, UsdGeom, _, _, _ = pxr_modules()
    if points is None:
        points = np.array(UsdGeom.Mesh(prim).GetPointsAttr().Get(time) or [], dtype=np.float64).reshape(-1, 3)
    world = _matrix(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(time))
    return points @ world[:3, :3] + world[3, :3]


def _mesh(prim, ctx: ReadContext, max_vertices: int, max_faces: int, time=None, skin: bool = True
          ) -> dict[str, np.ndarray]:
    """Vertices (bind pose, world), fan triangles and the skin of one Mesh prim, at ``time`` (a ``Usd.TimeCode``;
    the default time when None); ``skin`` False reads the points through the mesh's world transform alone."""
    Usd, UsdGeom, _, _, _ = pxr_modules()
    from pxr import UsdSkel

    mesh = UsdGeom.Mesh(prim)
    where = str(prim.GetPath())
    counts = np.array(mesh.GetFaceVertexCountsAttr().Get() or [], dtype=np.int64)
    indices = np.array(mesh.GetFaceVertexIndicesAttr().Get() or [], dtype=np.int64)
    time = still_time(mesh.GetPointsAttr()) if time is None else time
    points = np.array(mesh.GetPointsAttr().Get(time) or [], dtype=np.float64).reshape(-1, 3)
    check_counts(len(points), int(np.maximum(counts - 2, 0).sum()), ctx.source, max_vertices, max_faces)
    if (counts < 0).any() or counts.sum() != len(indices):
        raise ctx.error(f"{where}: faceVertexCounts add up to {int(counts.sum()):,} corners, the mesh has "
                        f"{len(indices):,} faceVertexIndices", "bad_faces")
    if len(indices) and (indices.min() < 0 or indices.max() >= len(points)):
        raise ctx.error(f"{where}: a face refers to a point outside its {len(points):,} points", "bad_faces")
    faces = fan_triangles(counts, indices)
    binding = UsdSkel.BindingAPI(prim)
    skeleton = binding.GetInheritedSkeleton() if skin and _skinned(prim) else None
    if skeleton is None:
        return {"vertices": _world_points(prim, time, points), "faces": faces}
    geom_bind = binding.GetGeomBindTransformAttr().Get()
    geom_bind = np.eye(4) if geom_bind is None else _matrix(geom_bind)
    skeleton_world = _matrix(UsdGeom.Xformable(skeleton.GetPrim()).ComputeLocalToWorldTransform(time))
    to_world = geom_bind @ skeleton_world  # row vectors: mesh space -> skeleton space -> world
    vertices = points @ to_world[:3, :3] + to_world[3, :3]
    return {"vertices": vertices, "faces": faces, **_skin(binding, skeleton, skeleton_world, vertices, where, ctx)}


def _skin(binding, skeleton, skeleton_world: np.ndarray, vertices: np.ndarray, where: str,
          ctx: ReadContext) -> dict[str, np.ndarray]:
    """Bones (world, file units) and weight triplets of a skinned mesh."""
    joints = [str(joint) for joint in skeleton.GetJointsAttr().Get() or []]
    if not joints:
        raise ctx.error(f"{skeleton.GetPath()}: the skeleton has no joints", "bad_skeleton")
    if len(joints) > MAX_BONES:
        raise ctx.error(f"the skeleton has {len(joints):,} joints, more than {MAX_BONES:,}", "too_large")
    if len(set(joints)) != len(joints):
        raise ctx.error(f"{skeleton.GetPath()}: a joint path appears twice", "bad_skeleton")
    bind = np.array(skeleton.GetBindTransformsAttr().Get() or [], dtype=np.float64).reshape(-1, 4, 4)
    if len(bind) != len(joints):
        raise ctx.error(f"{skeleton.GetPath()}: {len(bind)} bindTransforms for {len(joints)} joints", "bad_skeleton")
    if not np.isfinite(bind).all():
        raise ctx.error(f"{skeleton.GetPath()}: a bind transform is not finite", "non_finite")
    bind_world = bind @ skeleton_world
    heads = bind_world[:, 3, :3]
    position = {path: b for b, path in enumerate(joints)}
    parents = np.array([position.get(path.rsplit("/", 1)[0], -1) if "/" in path else -1 for path in joints],
                       dtype=np.int64)
    diagonal = float(np.linalg.norm(np.ptp(vertices, axis=0))) if len(vertices) else 1.0
    tails = bone_tails(heads, parents, bind_world.transpose(0, 2, 1), diagonal)  # column-vector convention there
    names = unique_names([path.rsplit("/", 1)[-1] for path in joints])
    rows, columns, values = _weights(binding, joints, len(vertices), where, ctx)
    return {"bone_names": np.array(names), "bone_parents": parents, "bone_heads": heads, "bone_tails": tails,
            "weight_rows": rows, "weight_columns": columns, "weight_values": values}


def _weights(binding, joints: list[str], n_vertices: int, where: str, ctx: ReadContext):
    """``(rows, columns, values)`` of the skin weights, columns in the skeleton's joint order."""
    index_primvar, weight_primvar = binding.GetJointIndicesPrimvar(), binding.GetJointWeightsPrimvar()
    indices = np.array(index_primvar.Get() or [], dtype=np.int64)
    weights = np.array(weight_primvar.Get() or [], dtype=np.float64) if weight_primvar else np.zeros(0)
    influences = max(1, int(index_primvar.GetElementSize()))
    if len(indices) != len(weights):
        raise ctx.error(f"{where}: {len(indices):,} joint indices but {len(weights):,} joint weights", "bad_weights")
    if index_primvar.GetInterpolation() == "constant":
        indices, weights = np.tile(indices, n_vertices), np.tile(weights, n_vertices)
    if len(indices) != n_vertices * influences:
        raise ctx.error(f"{where}: {len(indices):,} joint influences for {n_vertices:,} points of {influences} "
                        "each", "bad_weights")
    if not np.isfinite(weights).all() or (weights < 0).any():
        raise ctx.error(f"{where}: a negative or non-finite joint weight", "bad_weights")
    local = binding.GetJointsAttr().Get()
    if local:  # the mesh's own joint order: map it onto the skeleton's
        order = {path: b for b, path in enumerate(joints)}
        missing = [str(path) for path in local if str(path) not in order]
        if missing:
            raise ctx.error(f"{where}: skel:joints names {missing[0]!r}, not a joint of the skeleton", "bad_weights")
        mapping = np.array([order[str(path)] for path in local], dtype=np.int64)
    else:
        mapping = np.arange(len(joints), dtype=np.int64)
    used = weights > 0
    if used.any() and (indices[used].min() < 0 or indices[used].max() >= len(mapping)):
        raise ctx.error(f"{where}: a joint index outside the {len(mapping)} joints", "bad_weights")
    rows = np.repeat(np.arange(n_vertices, dtype=np.int64), influences)[used]
    return rows, mapping[indices[used]], weights[used]


READERS = {".usd": read_usd, ".usda": read_usd, ".usdc": read_usd}
