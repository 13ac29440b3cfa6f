"""Wrap: a source body's topology in a target's shape, for targets of another mesh topology.

:func:`wrap_body` registers the source mesh non-rigidly onto the target's surface
(optimal-step non-rigid ICP, Amberg, Romdhani & Vetter 2007) and returns the source's
vertices moved onto the target: the same vertex count and faces as the source, so the
same-topology retarget applies to it. Only the part of the source the hair needs is fitted
(``region``, e.g. :func:`~.region.hair_region`); the rest follows smoothly. The stages, one
module each:

- :mod:`.start`: the start, a similarity from the two heads (or landmarks), refined by ICP;
- :mod:`.landmarks`: landmark pairs bound to the source, or derived from the heads;
- :mod:`.nricp`: the stiff-to-soft loop, on :mod:`.system` (the normal equations on a
  fixed pattern), :mod:`.factor` (the sparse factorisation) and :mod:`.surface` (closest
  target points, their normals, the target's border);
- :mod:`.region`: the fitted region and how the rest follows;
- :mod:`.result`: :class:`WrapResult`, the residual, and :func:`check_wrap` (refusal).

Pure arrays in and out: no files, no caching.
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from hairport.solver.body.head_frame import mesh_head_frame
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError
from hairport.solver.wrap.landmarks import Landmarks, bind_landmarks, derived_landmarks
from hairport.solver.wrap.nricp import fit
from hairport.solver.wrap.options import WrapOptions
from hairport.solver.wrap.region import follow, hair_region, region_mesh
from hairport.solver.wrap.result import WrapResult, check_wrap, surface_residual
from hairport.solver.wrap.start import start_similarity
from hairport.solver.wrap.surface import TargetSurface, outer_faces

__all__ = ["WrapOptions", "WrapResult", "check_wrap", "hair_region", "wrap_body"]

#: a fitted region needs at least this many vertices on whole faces (one tetrahedron's worth
#: fixes an affine map; fewer leave the fit undetermined)
MIN_REGION_VERTICES = 4


def wrap_body(source_vertices: np.ndarray, source_faces: np.ndarray, target_vertices: np.ndarray,
              target_faces: np.ndarray, region: np.ndarray | None = None, landmarks: dict | None = None,
              options: WrapOptions = WrapOptions()) -> WrapResult:
    """Wrap the source body onto the target's surface.

    Parameters
    ----------
    source_vertices : (V, 3) float64
        Meters, hairport's canonical axes (Y up, the face toward +Z).
    source_faces : (F, 3) int64
    target_vertices : (W, 3) float64
        Meters, the same axes; any topology, open (a head cut at the neck, a bust) or closed.
    target_faces : (G, 3) int64
    region : (V,) bool, optional
        Source vertices to fit (e.g. :func:`~.region.hair_region`); by default all.
    landmarks : dict of str to ((3,), (3,)), optional
        Source point and target point (m) that must meet, per name.
    options : WrapOptions

    Returns
    -------
    result : WrapResult

    Raises
    ------
    InputError
        ``bad_mesh`` / ``non_finite`` for unusable arrays, ``not_a_head`` when a head frame
        cannot be read, ``bad_region`` for a region without faces, ``wrap_failed`` when the
        residual shows the target's shape was not reached (``options.refuse``).
    """
    began = time.perf_counter()
    source = Character(source_vertices, source_faces, name="source")
    target = Character(target_vertices, target_faces, name="target")
    region = _region_mask(region, source.n_vertices)
    fitted, triangles, edges = region_mesh(source.faces, region)
    if len(fitted) < MIN_REGION_VERTICES:
        raise InputError(f"the region holds {len(fitted)} vertices on whole faces; at least "
                         f"{MIN_REGION_VERTICES} are needed", "region", "bad_region")
    frames = (mesh_head_frame(source), mesh_head_frame(target))
    surface = TargetSurface(target.vertices, outer_faces(target.vertices, target.faces))
    pairs = dict(landmarks or {})
    if not pairs and options.derive_landmarks:
        pairs = derived_landmarks(source.vertices, frames[0], target.vertices, frames[1])
        options = replace(options, landmark_weights=options.derived_landmark_weights)
    head_ids, head_triangles, _ = region_mesh(source.faces, region & frames[0].head_vertices)
    start = start_similarity(source.vertices, (head_ids, head_triangles), frames, surface, pairs, options)
    moved = start.apply(source.vertices)
    bound = bind_landmarks(pairs, source.vertices, source.faces, fitted)
    positions, log = fit(moved[fitted], triangles, edges, surface, bound, options)
    wrapped = follow(moved, source.faces, fitted, positions)
    residual = surface_residual(positions, triangles, surface, np.cos(np.radians(options.max_normal_angle_deg)))
    result = WrapResult(wrapped, region, residual, _landmark_errors(bound, positions), log.iterations,
                        log.factorisations, time.perf_counter() - began, start)
    if options.refuse:
        check_wrap(result, "target")
    return result


def _landmark_errors(bound: Landmarks, positions: np.ndarray) -> dict[str, float]:
    """Distance (m) from each bound landmark's wrapped point (``positions (n, 3)`` of the patch) to its target."""
    wrapped = np.einsum("kc,kcj->kj", bound.weights, positions[bound.corners])
    return {name: float(d) for name, d in zip(bound.names, np.linalg.norm(wrapped - bound.targets, axis=1))}


def _region_mask(region: np.ndarray | None, n_vertices: int) -> np.ndarray:
    """(V,) bool: the region, all vertices by default; ``bad_region`` for a wrong shape."""
    if region is None:
        return np.ones(n_vertices, dtype=bool)
    region = np.asarray(region)
    if region.shape != (n_vertices,) or region.dtype != bool:
        raise InputError(f"the region is {region.dtype} of shape {region.shape}; expected bool of shape "
                         f"({n_vertices},)", "region", "bad_region")
    return region
