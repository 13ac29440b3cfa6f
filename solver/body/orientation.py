"""Which axes of an input point up and to the front, inferred from the body and its groom.

Inputs are axis-aligned in practice (DCC exports, scans: Y up or Z up, sometimes X up), so
each direction is estimated as a vector and snapped to the nearest signed coordinate axis;
the cosine between the estimate and the axis is its confidence.

Up
    The skeleton's ``head`` bone when there is one (it runs from the neck to the crown).
    Otherwise three cues, each a unit vector, summed: the roots sit above the body's centre
    (strong on a full body or a bust, up-and-back on a head alone), hair hangs down (the mean
    root-minus-tip direction; up-and-forward, as hair falls down the back), and an open
    boundary (a head cut at the neck, a bust cut at the chest) lies below the body's centre.
    On MakeHuman heads cut at the neck the first cue alone leans 30-38 degrees back, close to
    the 45 degrees where snapping fails; the other two lean forward and cancel that.
Front
    The face is where no hair grows: the roots sit behind the head's centre (the centre of
    the body surface near them), and the hair hangs toward the back. The side axis, across
    which a body is mirror-symmetric, is found first by reflecting the head's vertices
    (:func:`mirror_asymmetry`); the cues then give the sign of the remaining axis. When the
    cues are too weak, the convention of the up axis (:data:`FRONT_BY_CONVENTION`) is used.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from hairport.solver.mesh.topology import boundary_edges, half_edges
from hairport.solver.model.character import Character
from hairport.solver.model.frame import AXIS_VECTORS, axis_name
from hairport.solver.model.hair import Hair

#: the front axis assumed when the cues cannot tell, per up axis: glTF / Maya / MakeHuman (Y up,
#: the face toward +Z) and Blender / 3ds Max (Z up, the face toward -Y)
FRONT_BY_CONVENTION = {"+y": "+z", "-y": "-z", "+z": "-y", "-z": "+y", "+x": "+z", "-x": "+z"}
#: the head region is the body surface within this many scalp extents of the roots' centre
HEAD_REGION_SCALP_SHARES = 1.0
#: the side axis is the one across which the head is mirror-symmetric; it is trusted when the
#: other horizontal axis is at least this many times less symmetric (MakeHuman: 6-20)
SYMMETRY_CLEAR_RATIO = 2.0
#: below this confidence (cosine between the estimate and the axis) an axis is reported as
#: uncertain (a warning names the option that sets it)
CONFIDENT_COSINE = 0.8
#: front cues weaker than this (length of the summed cues) fall back to the convention
MIN_FRONT_CUE = 0.1
#: the roots' offset behind the head's centre counts fully from this share of the head's extent
#: (MakeHuman: 2-4 cm of 20 cm, 0.1-0.2); smaller offsets count in proportion
MIN_OFFSET_SHARE = 0.05
#: at most this many head vertices are reflected for the symmetry test
SYMMETRY_SAMPLE = 4000


@dataclass(frozen=True)
class AxesGuess:
    """Inferred (or given) up and front axes of an input.

    Attributes
    ----------
    up, front : str
        Axis names (``+x`` ... ``-z``).
    up_how, front_how : str
        Where each came from (``given``, ``head bone``, ``roots and hair``, ``face side``,
        ``convention``).
    up_confidence, front_confidence : float
        Cosine between the estimate and the axis (1 when given).
    """

    up: str
    front: str
    up_how: str
    front_how: str
    up_confidence: float = 1.0
    front_confidence: float = 1.0

    def warnings(self) -> list[str]:
        """One line per uncertain axis, naming the option that sets it."""
        notes = []
        if self.up_confidence < CONFIDENT_COSINE:
            notes.append(f"the up axis is uncertain (inferred {self.up} from {self.up_how}, confidence "
                         f"{self.up_confidence:.2f}); give it with --up-axis if it is wrong")
        if self.front_confidence < CONFIDENT_COSINE:
            notes.append(f"the front axis is uncertain (inferred {self.front} from {self.front_how}, confidence "
                         f"{self.front_confidence:.2f}); give it with --front-axis if it is wrong")
        return notes


def _unit(vector: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(vector)
    return vector / norm if norm > 0 else np.zeros_like(vector)


def _area_centroid(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(3,) area-weighted centroid of a triangle set (the vertex mean for a degenerate one)."""
    triangles = vertices[faces]
    area = 0.5 * np.linalg.norm(np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0]), axis=1)
    if area.sum() <= 0:
        return vertices.mean(axis=0)
    return (triangles.mean(axis=1) * area[:, None]).sum(axis=0) / area.sum()


def hang_direction(hair: Hair) -> np.ndarray:
    """(3,) mean of the strands' unit root-minus-tip directions (up, where hair hangs)."""
    along = hair.points[hair.roots] - hair.points[hair.offsets[1:] - 1]
    norm = np.linalg.norm(along, axis=1, keepdims=True)
    return (along / np.where(norm > 0, norm, 1.0)).mean(axis=0) if len(along) else np.zeros(3)


def up_cues(character: Character, hair: Hair) -> np.ndarray:
    """(3,) the sum of the unit up cues (roots above the centre, hair hanging, boundary below)."""
    vertices, faces = character.vertices, character.faces
    centre = _area_centroid(vertices, faces)
    cue = _unit(hair.points[hair.roots].mean(axis=0) - centre) + _unit(hang_direction(hair))
    open_edges = half_edges(faces)[boundary_edges(faces, len(vertices)).ravel()]
    if len(open_edges):
        cue = cue + _unit(centre - vertices[open_edges].reshape(-1, 3).mean(axis=0))
    return cue


def infer_up(character: Character, hair: Hair) -> tuple[str, str, float]:
    """The up axis: along the ``head`` bone when there is one, else from :func:`up_cues`.

    Returns
    -------
    axis : str
    how : str
    confidence : float
        Cosine between the estimate and the axis.
    """
    skeleton = character.skeleton
    if skeleton is not None and "head" in skeleton.names:
        head = skeleton.index("head")
        estimate, how = skeleton.tails[head] - skeleton.heads[head], "the head bone"
    else:
        estimate, how = up_cues(character, hair), "the roots, the hang of the hair and the mesh's open edges"
    if not np.linalg.norm(estimate) > 0:
        return "+y", "convention", 0.0
    axis = axis_name(estimate)
    return axis, how, float(_unit(estimate) @ AXIS_VECTORS[axis])


def head_region(character: Character, hair: Hair) -> np.ndarray:
    """(K,) indices of the faces near the roots (the head)."""
    roots = hair.points[hair.roots]
    centre = roots.mean(axis=0)
    radius = HEAD_REGION_SCALP_SHARES * float((roots.max(axis=0) - roots.min(axis=0)).max())
    face_centres = character.vertices[character.faces].mean(axis=1)
    near = np.flatnonzero(np.linalg.norm(face_centres - centre, axis=1) <= radius)
    if len(near) == 0:
        near = np.argsort(np.linalg.norm(face_centres - centre, axis=1))[: max(1, len(face_centres) // 10)]
    return near


def mirror_asymmetry(points: np.ndarray, axis: np.ndarray) -> float:
    """Mean distance from the points mirrored across the plane through their centre normal to
    ``axis`` to the nearest point, as a share of their extent (0 for a mirror-symmetric set)."""
    points = np.asarray(points, dtype=np.float64)
    if len(points) > SYMMETRY_SAMPLE:
        points = points[:: len(points) // SYMMETRY_SAMPLE + 1]
    centre = points.mean(axis=0)
    mirrored = points - 2.0 * ((points - centre) @ axis)[:, None] * axis
    distance, _ = cKDTree(points).query(mirrored)
    extent = float((points.max(axis=0) - points.min(axis=0)).max())
    return float(distance.mean() / extent) if extent > 0 else 0.0


def front_cues(character: Character, hair: Hair, up: str) -> np.ndarray:
    """(3,) the sum of the front cues, normal to ``up``: away from the roots' offset from the
    head's centre (unit length from :data:`MIN_OFFSET_SHARE` of the head's extent), and the
    horizontal part of the hair's hang (hair falls to the back)."""
    up_vector = AXIS_VECTORS[up]
    region = head_region(character, hair)
    region_points = character.vertices[character.faces[region]].reshape(-1, 3)
    centre = _area_centroid(character.vertices, character.faces[region])
    offset = hair.points[hair.roots].mean(axis=0) - centre
    offset = offset - (offset @ up_vector) * up_vector
    # a unit vector for an offset of a few per cent of the head or more, shorter below
    reference = MIN_OFFSET_SHARE * float((region_points.max(axis=0) - region_points.min(axis=0)).max())
    hang = hang_direction(hair)
    cue = -offset / max(float(np.linalg.norm(offset)), reference, 1e-12) + (hang - (hang @ up_vector) * up_vector)
    return cue - (cue @ up_vector) * up_vector


def infer_front(character: Character, hair: Hair, up: str) -> tuple[str, str, float]:
    """The front axis, normal to ``up`` (see the module notes).

    Returns
    -------
    axis : str
    how : str
    confidence : float
        Cosine between the cues and the axis (the symmetry test's when it decided the axis).
    """
    up_vector = AXIS_VECTORS[up]
    horizontal = [i for i in range(3) if up_vector[i] == 0]
    cue = front_cues(character, hair, up)
    if np.linalg.norm(cue) < MIN_FRONT_CUE:
        return FRONT_BY_CONVENTION[up], "convention", 0.0
    region_vertices = np.unique(character.faces[head_region(character, hair)])
    points = character.vertices[region_vertices]
    asymmetry = {i: mirror_asymmetry(points, np.eye(3)[i]) for i in horizontal}
    side, other = sorted(horizontal, key=asymmetry.get)
    if asymmetry[other] >= SYMMETRY_CLEAR_RATIO * asymmetry[side]:
        axis = ("+" if cue[other] >= 0 else "-") + "xyz"[other]
        confidence = abs(cue[other]) / np.linalg.norm(cue)
        return axis, "the face side (mirror symmetry and the roots)", float(max(confidence, 1.0 - asymmetry[side]
                                                                                / max(asymmetry[other], 1e-12)))
    axis = axis_name(cue)
    return axis, "the roots and the hang of the hair", float(_unit(cue) @ AXIS_VECTORS[axis])


def infer_axes(character: Character, hair: Hair, up: str | None = None, front: str | None = None) -> AxesGuess:
    """Up and front axes of a character and the groom made for it (each given or inferred).

    Parameters
    ----------
    character : Character
        In its own axes (any units).
    hair : Hair
        In the same axes and units.
    up, front : str, optional
        Given axes (normalised names); the other is inferred.

    Returns
    -------
    guess : AxesGuess
    """
    if up is None:
        up, up_how, up_confidence = infer_up(character, hair)
    else:
        up_how, up_confidence = "given", 1.0
    if front is None:
        front, front_how, front_confidence = infer_front(character, hair, up)
    else:
        front_how, front_confidence = "given", 1.0
    return AxesGuess(up, front, up_how, front_how, up_confidence, front_confidence)


def relative_axes(reference: np.ndarray, vertices: np.ndarray) -> tuple[str, str, float]:
    """The axes of a mesh relative to a reference of the same topology in the canonical frame.

    The rotation that best maps the centred ``vertices`` onto the centred ``reference``
    (Kabsch), snapped to the nearest signed permutation.

    Parameters
    ----------
    reference : (V, 3) float64
        Canonical frame.
    vertices : (V, 3) float64
        The same vertices in the input's axes (any uniform scale).

    Returns
    -------
    up, front : str
        The input axes that map to canonical +Y and +Z.
    confidence : float
        The smaller cosine between the fitted canonical up/front and the snapped axes.
    """
    a = vertices - vertices.mean(axis=0)
    b = reference - reference.mean(axis=0)
    u, _, vt = np.linalg.svd(a.T @ b)
    d = np.sign(np.linalg.det(u @ vt)) or 1.0
    rotation = (u @ np.diag([1.0, 1.0, d]) @ vt).T  # canonical = rotation @ input
    up_estimate, front_estimate = rotation[1], rotation[2]
    up = axis_name(up_estimate)
    front_estimate = front_estimate - (front_estimate @ AXIS_VECTORS[up]) * AXIS_VECTORS[up]
    front = axis_name(front_estimate)
    confidence = min(float(_unit(up_estimate) @ AXIS_VECTORS[up]), float(_unit(front_estimate) @ AXIS_VECTORS[front]))
    return up, front, confidence
