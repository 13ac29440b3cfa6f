"""USD scenes written with usd-core directly, as a DCC tool exports them: a skinned UsdGeom.Mesh with its
UsdSkel skeleton (and optionally a BasisCurves groom) under a translated Xform, in centimetres, Z-up."""

from __future__ import annotations

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt

#: canonical (Y-up, meters) -> the stage's Z-up axes: x stays, y becomes z, z becomes -y
Y_UP_TO_Z_UP = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
XFORM_TRANSLATION_CM = (12.5, -40.0, 7.0)


def to_stage(points: np.ndarray, scale: float) -> np.ndarray:
    """Canonical meters -> the stage's local coordinates (Z-up, its units, minus the Xform's translation)."""
    return points @ Y_UP_TO_Z_UP / scale - np.array(XFORM_TRANSLATION_CM) * 0.01 / scale


def joint_paths(names, parents) -> list[str]:
    paths: list[str] = []
    for name, parent in zip(names, parents, strict=True):
        paths.append(name if parent < 0 else f"{paths[parent]}/{name}")
    return paths


def write_scene(path, character, hair=None, *, meters_per_unit: float = 0.01, skinned: bool = True,
                extra_mesh: bool = False) -> None:
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    root = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(root.GetPrim())
    xform = UsdGeom.Xform.Define(stage, "/World/character")
    xform.AddTranslateOp().Set(Gf.Vec3d(*(np.array(XFORM_TRANSLATION_CM) * 0.01 / meters_per_unit)))
    skel_root = UsdSkel.Root.Define(stage, "/World/character/rig")
    mesh = UsdGeom.Mesh.Define(stage, "/World/character/rig/body")
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(to_stage(character.vertices, meters_per_unit).astype(np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(character.faces), 3, dtype=np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(character.faces.astype(np.int32).ravel()))
    if extra_mesh:  # a small prop: the reader must pick the skinned body
        prop = UsdGeom.Mesh.Define(stage, "/World/character/prop")
        prop.CreatePointsAttr(Vt.Vec3fArray([Gf.Vec3f(0, 0, 0), Gf.Vec3f(1, 0, 0), Gf.Vec3f(0, 1, 0)]))
        prop.CreateFaceVertexCountsAttr(Vt.IntArray([3]))
        prop.CreateFaceVertexIndicesAttr(Vt.IntArray([0, 1, 2]))
    if skinned and character.skeleton is not None:
        skeleton = character.skeleton
        usd_skeleton = UsdSkel.Skeleton.Define(stage, "/World/character/rig/skeleton")
        paths = joint_paths(skeleton.names, skeleton.parents)
        usd_skeleton.CreateJointsAttr(Vt.TokenArray(paths))
        heads = to_stage(skeleton.heads, meters_per_unit)
        bind = [Gf.Matrix4d(1.0).SetTranslateOnly(Gf.Vec3d(*map(float, head))) for head in heads]
        usd_skeleton.CreateBindTransformsAttr(Vt.Matrix4dArray(bind))
        usd_skeleton.CreateRestTransformsAttr(Vt.Matrix4dArray(bind))
        binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
        binding.CreateSkeletonRel().SetTargets([usd_skeleton.GetPath()])
        weights = character.weights.tocsr()
        influences = int(np.diff(weights.indptr).max())
        indices = np.zeros((weights.shape[0], influences), dtype=np.int32)
        values = np.zeros((weights.shape[0], influences), dtype=np.float32)
        for row in range(weights.shape[0]):
            start, end = weights.indptr[row], weights.indptr[row + 1]
            indices[row, : end - start] = weights.indices[start:end]
            values[row, : end - start] = weights.data[start:end]
        binding.CreateJointIndicesPrimvar(False, influences).Set(Vt.IntArray.FromNumpy(indices.ravel()))
        binding.CreateJointWeightsPrimvar(False, influences).Set(Vt.FloatArray.FromNumpy(values.ravel()))
        binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))
        UsdSkel.BindingAPI.Apply(skel_root.GetPrim())
    if hair is not None:
        curves = UsdGeom.BasisCurves.Define(stage, "/World/character/groom")
        curves.CreateTypeAttr(UsdGeom.Tokens.linear)
        curves.CreateCurveVertexCountsAttr(Vt.IntArray.FromNumpy(hair.counts.astype(np.int32)))
        curves.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(to_stage(hair.points, meters_per_unit).astype(np.float32)))
        primvars = UsdGeom.PrimvarsAPI(curves.GetPrim())
        primvars.CreatePrimvar("strand_id", Sdf.ValueTypeNames.IntArray, UsdGeom.Tokens.uniform).Set(
            Vt.IntArray.FromNumpy(np.arange(hair.n_strands, dtype=np.int32)))
    stage.GetRootLayer().Save()


def add_skel_animation(path, character, other, times, drift_cm: float) -> None:
    """Pose the skinned body of a :func:`write_scene` stage (centimetres) by a ``UsdSkel.Animation``: a blend shape
    toward ``other`` weighted ``0 .. 1`` over ``times``, and the root joint translated ``drift_cm`` a time sample
    along the stage's X."""
    stage = Usd.Stage.Open(str(path))
    mesh = stage.GetPrimAtPath("/World/character/rig/body")
    skeleton = UsdSkel.Skeleton(stage.GetPrimAtPath("/World/character/rig/skeleton"))
    animation = UsdSkel.Animation.Define(stage, "/World/character/rig/skeleton/animation")
    paths = list(skeleton.GetJointsAttr().Get())
    heads = np.array([matrix.ExtractTranslation() for matrix in skeleton.GetRestTransformsAttr().Get()])
    parents = character.skeleton.parents
    local = np.array([heads[b] - (heads[parents[b]] if parents[b] >= 0 else 0.0) for b in range(len(paths))])
    animation.CreateJointsAttr(Vt.TokenArray(paths))
    animation.CreateBlendShapesAttr(Vt.TokenArray(["other"]))
    animation.CreateRotationsAttr(Vt.QuatfArray([Gf.Quatf(1, 0, 0, 0)] * len(paths)))
    animation.CreateScalesAttr(Vt.Vec3hArray([Gf.Vec3h(1, 1, 1)] * len(paths)))
    translations, weights = animation.CreateTranslationsAttr(), animation.CreateBlendShapeWeightsAttr()
    roots = parents < 0
    for number, (time, weight) in enumerate(zip(times, np.linspace(0.0, 1.0, len(times)), strict=True)):
        moved = local.copy()
        moved[roots, 0] += drift_cm * number
        translations.Set(Vt.Vec3fArray.FromNumpy(moved.astype(np.float32)), time)
        weights.Set(Vt.FloatArray([float(weight)]), time)
    UsdSkel.BindingAPI.Apply(skeleton.GetPrim()).CreateAnimationSourceRel().SetTargets([animation.GetPath()])
    shape = UsdSkel.BlendShape.Define(stage, "/World/character/rig/body/other")
    offsets = (to_stage(other.vertices, 0.01) - to_stage(character.vertices, 0.01)).astype(np.float32)
    shape.CreateOffsetsAttr(Vt.Vec3fArray.FromNumpy(offsets))
    binding = UsdSkel.BindingAPI(mesh)
    binding.CreateBlendShapesAttr(Vt.TokenArray(["other"]))
    binding.CreateBlendShapeTargetsRel().SetTargets([shape.GetPath()])
    stage.GetRootLayer().Save()
