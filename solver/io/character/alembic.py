"""Alembic animated meshes (``.abc``) as the frames of a target sequence: one ``IPolyMesh`` whose positions are
sampled over time, through the ``alembic3d`` bindings (the optional extra, as for Alembic hair).

The mesh: the one ``mesh_name`` names (object name or full path), else the one with the most vertices (a tie is
``ambiguous_mesh``). Its faces are fan-triangulated in file order with the winding reversed (Alembic winds polygons
clockwise; hairport's faces are counter-clockwise seen from outside), its positions taken at each frame's time
(frame ``f`` at ``f / 24`` seconds; between two samples, linearly between them) through the ``IXform`` objects above
it at that time (their nearest samples). Alembic records no length unit: the frames' units are inferred as for any
mesh without one. No skin is read.

Parsing runs in a memory- and time-limited child (:mod:`~hairport.solver.io.sandbox`), as every Alembic read.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from hairport.solver.io.character.mesh_file import MeshFile, check_counts, fan_triangles
from hairport.solver.io.external import ALLOW_EXTERNAL_FILES
from hairport.solver.io.hair.alembic import opened_archive, require_alembic
from hairport.solver.io.hair.alembic.params import numpy_copy
from hairport.solver.io.hair.common import ReadContext, ReadLimits
from hairport.solver.io.sandbox import run_in_child


def read_alembic_frames(path: Path, times_s: list[float], *, max_vertices: int, max_faces: int,
                        mesh_name: str | None, allow_external_files: bool = ALLOW_EXTERNAL_FILES) -> list[MeshFile]:
    """The archive's mesh at each time (seconds; module notes), parsed in a limited child.

    Raises
    ------
    InputError
        ``format_unavailable`` without the bindings, ``bad_header`` for a damaged archive, ``empty_mesh`` for one
        without a polygon mesh, ``not_animated`` for a mesh of fewer than two samples, ``bad_frames`` for times
        outside its samples, ``sequence_topology`` for samples of other faces.
    """
    found = _read_in_child(path, [float(t) for t in times_s], max_vertices, max_faces, mesh_name, allow_external_files)
    label = str(found["label"])
    return [MeshFile(points, found["faces"], None, f"{label}@{time:g}s", None)
            for points, time in zip(found["frames"], times_s, strict=True)]


def read_alembic(path: Path, *, max_vertices: int, max_faces: int, mesh_name: str | None,
                 allow_external_files: bool = ALLOW_EXTERNAL_FILES) -> MeshFile:
    """The archive's mesh as one body: at its first sample (a still mesh's only one), parsed in a limited child; no
    units (Alembic records none), no skin."""
    found = _read_in_child(path, None, max_vertices, max_faces, mesh_name, allow_external_files)
    return MeshFile(found["frames"][0], found["faces"], None, str(found["label"]), None)


def _read_in_child(path: Path, times: list[float] | None, max_vertices: int, max_faces: int, mesh_name: str | None,
                   allow_external_files: bool) -> dict[str, np.ndarray]:
    """:func:`mesh_frames` of an archive, in the limited child (``format_unavailable`` without the bindings)."""
    source = str(path)
    require_alembic(source)
    arguments = {"name": path.name, "times": times, "max_vertices": max_vertices, "max_faces": max_faces,
                 "mesh_name": mesh_name, "allow_external_files": allow_external_files}
    return run_in_child(__name__, "mesh_frames", source, os.path.getsize(source), arguments, source, "Alembic")


def mesh_frames(source: str, name: str, times: list[float] | None, max_vertices: int, max_faces: int,
                mesh_name: str | None, allow_external_files: bool = ALLOW_EXTERNAL_FILES) -> dict[str, np.ndarray]:
    """In the child: the mesh's faces and its world positions at each time, or (``times`` None) at its first sample
    (read back by :func:`read_alembic_frames` and :func:`read_alembic`)."""
    from alembic3d import Abc, AbcGeom

    ctx = ReadContext(name, ReadLimits(), "m")
    with opened_archive(source, ctx) as archive:
        meshes = []
        _collect(archive.getTop(), meshes, AbcGeom)
        obj = _chosen(meshes, mesh_name, ctx, Abc, AbcGeom)
        schema = AbcGeom.IPolyMesh(obj, Abc.WrapExistingFlag.kWrapExisting).getSchema()
        where, count = obj.getFullName(), schema.getNumSamples()
        if times is None and count > 0:
            first = schema.getTimeSampling().getSampleTime(0)
            faces, frames = _frames(obj, schema, np.array([first]), [first], ctx, max_vertices, max_faces, Abc,
                                    AbcGeom)
            return {"label": np.array(where), "faces": faces, "frames": frames}
        if times is None:
            raise ctx.error(f"{where}: no sample of its positions", "empty_mesh")
        if count < 2:
            raise ctx.error(f"{where}: {count} sample{'s' if count != 1 else ''} of its positions, so it is not "
                            "animated", "not_animated")
        sampling = schema.getTimeSampling()
        sample_times = np.array([sampling.getSampleTime(i) for i in range(count)])
        if min(times) < sample_times[0] - 1e-9 or max(times) > sample_times[-1] + 1e-9:
            raise ctx.error(f"{where}: frames at {min(times):g} to {max(times):g} s reach past its samples "
                            f"({sample_times[0]:g} to {sample_times[-1]:g} s)", "bad_frames")
        faces, frames = _frames(obj, schema, sample_times, times, ctx, max_vertices, max_faces, Abc, AbcGeom)
    return {"label": np.array(where), "faces": faces, "frames": frames}


def _frames(obj, schema, sample_times, times, ctx, max_vertices, max_faces, Abc, AbcGeom):
    first = schema.getValue(Abc.ISampleSelector(float(sample_times[0])))
    counts = numpy_copy(first.getFaceCounts()).astype(np.int64)
    indices = numpy_copy(first.getFaceIndices()).astype(np.int64)
    n_points = len(first.getPositions())
    check_counts(n_points, int(np.maximum(counts - 2, 0).sum()), ctx.source, max_vertices, max_faces)
    if (counts < 0).any() or counts.sum() != len(indices) or (len(indices) and (indices.min() < 0 or
                                                                               indices.max() >= n_points)):
        raise ctx.error(f"{obj.getFullName()}: its faces do not fit its {n_points:,} points", "bad_faces")
    faces = fan_triangles(counts, indices)[:, ::-1].copy()  # clockwise in Alembic
    frames = np.empty((len(times), n_points, 3))
    for number, time in enumerate(times):
        index = int(np.clip(np.searchsorted(sample_times, time, side="right") - 1, 0, max(len(sample_times) - 2, 0)))
        following = min(index + 1, len(sample_times) - 1)  # a still mesh's one sample is its own neighbour
        span = sample_times[following] - sample_times[index]
        weight = float(np.clip((time - sample_times[index]) / span, 0.0, 1.0)) if span > 0 else 0.0
        before, after = (_positions(schema, sample_times, i, counts, n_points, obj, ctx, Abc)
                         for i in (index, following))
        points = before + weight * (after - before)
        world = _world_matrix(obj, time, Abc, AbcGeom)
        frames[number] = points @ world[:3, :3] + world[3, :3]
    return faces, frames


def _positions(schema, sample_times: np.ndarray, index: int, counts: np.ndarray, n_points: int, obj, ctx,
               Abc) -> np.ndarray:
    """Sample ``index``'s positions ``(n_points, 3)``; ``sequence_topology`` for other points or face counts."""
    # by its time: the bindings read an int given to ISampleSelector as a time in seconds, not as an index
    sample = schema.getValue(Abc.ISampleSelector(float(sample_times[index])))
    points = numpy_copy(sample.getPositions()).astype(np.float64).reshape(-1, 3)
    if len(points) != n_points or not np.array_equal(numpy_copy(sample.getFaceCounts()), counts):
        raise ctx.error(f"{obj.getFullName()}: sample {index} has {len(points):,} points or other faces than sample 0: "
                        "the frames of a sequence must be one mesh", "sequence_topology")
    return points


def _world_matrix(obj, time: float, Abc, AbcGeom) -> np.ndarray:
    """(4, 4), row vectors: the ``IXform`` objects above ``obj`` at ``time`` (their nearest samples)."""
    matrix = np.eye(4)
    parent = obj.getParent()
    while parent is not None and parent.valid() and parent.getName() != "ABC":
        if AbcGeom.IXform.matches(parent.getHeader()):
            schema = AbcGeom.IXform(parent, Abc.WrapExistingFlag.kWrapExisting).getSchema()
            local = schema.getValue(Abc.ISampleSelector(time)).getMatrix()
            matrix = matrix @ np.array([[local[r][c] for c in range(4)] for r in range(4)])
            if not schema.getInheritsXforms():
                break
        parent = parent.getParent()
    return matrix


def _collect(obj, found: list, AbcGeom) -> None:
    for child in obj.children:
        if AbcGeom.IPolyMesh.matches(child.getHeader()):
            found.append(child)
        _collect(child, found, AbcGeom)


def _chosen(meshes: list, mesh_name: str | None, ctx: ReadContext, Abc, AbcGeom):
    if not meshes:
        raise ctx.error("the archive has no IPolyMesh object", "empty_mesh")
    if mesh_name is not None:
        chosen = [obj for obj in meshes if mesh_name in (obj.getName(), obj.getFullName())]
        if not chosen:
            names = ", ".join(repr(obj.getFullName()) for obj in meshes)
            raise ctx.error(f"no mesh named {mesh_name!r}; the archive has {names}", "bad_mesh")
        return chosen[0]
    sizes = [len(AbcGeom.IPolyMesh(obj, Abc.WrapExistingFlag.kWrapExisting).getSchema().getValue().getPositions())
             for obj in meshes]
    best = [obj for obj, size in zip(meshes, sizes, strict=True) if size == max(sizes)]
    if len(best) > 1:
        names = ", ".join(repr(obj.getFullName()) for obj in best)
        raise ctx.error(f"ambiguous: meshes {names} have {max(sizes)} vertices each; choose one with mesh_name",
                        "ambiguous_mesh")
    return best[0]



#: the still read of :mod:`~hairport.solver.io.character.load`, by extension
READERS = {".abc": read_alembic}
