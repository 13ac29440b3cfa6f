"""Landmarks of the wrap: bound to the fitted source patch, or derived from the two heads.

A landmark is a pair of points, one on the source, one on the target, that must meet. The
caller may give them (a name for each pair); :func:`head_landmarks` derives a few from a
head mesh alone, as the extreme points of the skull in hairport's canonical axes (Y up, the
face toward +Z), read in the head frame of
:func:`~hairport.solver.body.head_frame.mesh_head_frame`: the top of the skull (``vertex``),
its back (``back``: the farthest point behind, at mid-skull height), its widest points
(``left``, ``right``, at mid-skull height) and the tip of the nose (``nose``, the farthest
point in front near the face's midline). The same rule on two heads names roughly the same
anatomical points; an extreme point on a flat stretch is uncertain along it, so derived
landmarks only steer the stiff first steps (their weight falls to zero after). On the
MakeHuman presets they did not help (the top of the skull lands centimetres apart on two
heads) and are off by default (:attr:`~.options.WrapOptions.derive_landmarks`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hairport.solver.body.head_frame import HeadFrame
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.mesh.triangles import barycentric_coordinates

#: heights (share of the crown height above the head joint) of the skull band where the back
#: and the widest points are taken: above the ears, below the flat top
SKULL_BAND = (0.35, 0.75)
#: the nose is the farthest point in front within this share of the half-width of the midline,
#: between these heights (shares of the crown height; the chin lies lower, the brow higher)
NOSE_MIDLINE_SHARE = 0.25
NOSE_BAND = (-0.2, 0.35)


@dataclass(frozen=True)
class Landmarks:
    """Landmarks bound to the fitted patch: barycentric combinations of its vertices and their targets.

    Attributes
    ----------
    names : tuple of str
    corners : (k, 3) int64
        Local vertex ids.
    weights : (k, 3) float64
        Barycentric weights.
    targets : (k, 3) float64
        Target points (m).
    """

    names: tuple[str, ...]
    corners: np.ndarray
    weights: np.ndarray
    targets: np.ndarray

    @classmethod
    def none(cls) -> "Landmarks":
        return cls((), np.zeros((0, 3), np.int64), np.zeros((0, 3)), np.zeros((0, 3)))


def head_landmarks(vertices: np.ndarray, frame: HeadFrame) -> dict[str, np.ndarray]:
    """Extreme points of a head (module docstring), by name.

    Parameters
    ----------
    vertices : (V, 3) float64
        The mesh (m), canonical axes.
    frame : HeadFrame
        Its head frame; ``frame.head_vertices`` says which vertices are the head.

    Returns
    -------
    points : dict of str to (3,) float64
        ``vertex``, ``back``, ``left``, ``right``, ``nose`` (those whose band holds a vertex).
    """
    head = np.flatnonzero(frame.head_vertices)
    a, f, s = frame.local(vertices[head]).T
    height = a / frame.crown
    skull = (height >= SKULL_BAND[0]) & (height <= SKULL_BAND[1])
    nose = (height >= NOSE_BAND[0]) & (height <= NOSE_BAND[1]) & (np.abs(s) <= NOSE_MIDLINE_SHARE * frame.half_width)
    picks = {"vertex": (np.ones_like(skull), a), "back": (skull, -f), "left": (skull, s), "right": (skull, -s),
             "nose": (nose, f)}
    points = {}
    for name, (where, value) in picks.items():
        if where.any():
            points[name] = vertices[head[np.flatnonzero(where)[np.argmax(value[where])]]]
    return points


def derived_landmarks(source_vertices: np.ndarray, source_frame: HeadFrame, target_vertices: np.ndarray,
                      target_frame: HeadFrame) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Pairs (source point, target point) of :func:`head_landmarks` found on both heads."""
    source = head_landmarks(source_vertices, source_frame)
    target = head_landmarks(target_vertices, target_frame)
    return {name: (source[name], target[name]) for name in source if name in target}


def bind_landmarks(landmarks: dict, source_vertices: np.ndarray, source_faces: np.ndarray,
                   fitted: np.ndarray) -> Landmarks:
    """Landmark pairs bound to the fitted patch: each source point's closest point on the source
    mesh, as a barycentric combination of the patch's vertices.

    Parameters
    ----------
    landmarks : dict of str to ((3,), (3,))
        Source point and target point (m) per name.
    source_vertices : (V, 3) float64
        The source mesh where the source points were given (m).
    source_faces : (F, 3) int64
    fitted : (n,) int64
        Source ids of the patch's vertices, ascending.

    Returns
    -------
    landmarks : Landmarks
        Only the pairs whose source point lies on a face of the patch.
    """
    if not landmarks:
        return Landmarks.none()
    names = tuple(landmarks)
    source_points = np.array([np.asarray(landmarks[n][0], dtype=np.float64) for n in names]).reshape(-1, 3)
    targets = np.array([np.asarray(landmarks[n][1], dtype=np.float64) for n in names]).reshape(-1, 3)
    sd = MeshQuery(source_vertices, source_faces).signed_distance(source_points)
    corners = source_faces[sd.faces]
    local = np.searchsorted(fitted, corners)
    local = np.minimum(local, len(fitted) - 1)
    on_patch = (fitted[local] == corners).all(axis=1)
    weights = barycentric_coordinates(sd.closest, source_vertices[corners])
    keep = np.flatnonzero(on_patch)
    return Landmarks(tuple(names[i] for i in keep), local[keep], weights[keep], targets[keep])
