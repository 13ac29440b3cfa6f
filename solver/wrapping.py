"""A target of another topology in a retarget: the source body wrapped onto it, and which mesh each stage uses.

Correspondence comes from the wrap, contact from the real body. The wrap
(:func:`hairport.solver.wrap.wrap_body`) gives the source's mesh in the target's shape; every stage that needs
the source's vertices (anchoring and skeleton transfer, Eq. 2-3; the scalp and head chart of a hairline edit;
Eq. 20's weights) runs on it. Every stage that touches the body runs on the target itself: the roots are moved
onto its surface (each strand with its root, :func:`onto_body`), Eq. 13 and the final penetration check use
its collision surface, and the metrics measure against it.

Only the part of the source the hair can reach is fitted (:func:`reach_region`); the wrap is keyed by the
content of both bodies, the region and its options (:func:`wrap_key`), so callers keep it and hand it back
(:class:`WrappedTarget`) for another groom on the same pair of bodies.
"""

from __future__ import annotations

import hashlib
from dataclasses import asdict, dataclass

import numpy as np

from hairport.solver.adaptable import AdaptableHairstyle
from hairport.solver.mesh.collision import body_key
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.mesh.triangles import barycentric_coordinates, interpolate_barycentric
from hairport.solver.model.character import Character
from hairport.solver.model.degenerate import strand_lengths
from hairport.solver.model.errors import InputError
from hairport.solver.model.frame import InputFrame
from hairport.solver.model.hair import Hair
from hairport.solver.model.landmarks import BAD_LANDMARKS, LandmarkPairs
from hairport.solver.options import WRAP_MODES
from hairport.solver.wrap import WrapOptions, WrapResult, hair_region, wrap_body

WRAP_AUTO, WRAP_ALWAYS, WRAP_OFF = WRAP_MODES
#: the fitted region: source vertices within the longest strand's length of a hair particle, plus this margin (m)
REACH_MARGIN_M = 0.02
#: a landmark farther than this (m) from its mesh's surface is refused: it was given in other coordinates
#: than the mesh's file (units, axes), or on another mesh
LANDMARK_OFF_SURFACE_M = 0.02


@dataclass(frozen=True, eq=False)
class WrappedTarget:
    """A target of another topology, wrapped.

    Attributes
    ----------
    shape : Character
        The source's mesh (vertices, faces) in the target's shape, canonical frame; no skeleton (a
        retarget transfers the source's).
    key : str
        :func:`wrap_key` of the pair.
    report : dict
        The metrics' ``wrap`` section (JSON-ready, meters): residual, landmark errors, iterations, seconds.
    """

    shape: Character
    key: str
    report: dict


def is_same_topology(source: Character, target: Character) -> bool:
    return source.n_vertices == target.n_vertices and np.array_equal(source.faces, target.faces)


def needs_wrap(source: Character, target: Character, mode: str) -> bool:
    """Whether a retarget onto ``target`` wraps the source onto it (``mode``: one of :data:`WRAP_MODES`)."""
    if mode not in WRAP_MODES:
        raise InputError(f"unknown wrap mode {mode!r}; expected one of {', '.join(WRAP_MODES)}", code="bad_option")
    return mode == WRAP_ALWAYS or (mode == WRAP_AUTO and not is_same_topology(source, target))


def require_a_wrap_for(landmarks: LandmarkPairs | None, mode: str) -> None:
    """Refuse landmarks for a target that is not wrapped (under the wrap ``mode``): they would change nothing.

    Raises
    ------
    InputError
        ``bad_landmarks``.
    """
    if landmarks is not None:
        raise InputError(f"the target has the source's mesh topology and is not wrapped (wrap {mode}); landmarks "
                         f"steer a wrap: give wrap {WRAP_ALWAYS} to wrap it anyway", "landmarks", BAD_LANDMARKS)


def reach_region(source: Character, hair: Hair) -> np.ndarray:
    """(V,) bool: the source vertices the hair touches or can reach (within its longest strand's length)."""
    reach = float(strand_lengths(hair.points, hair.offsets).max(initial=0.0)) + REACH_MARGIN_M
    return hair_region(source.vertices, source.faces, hair.points, reach)


def content_key(source: Character, region: np.ndarray, target: Character, options: WrapOptions,
                landmarks: LandmarkPairs | None = None) -> str:
    """The content digest of a wrap: both bodies, the fitted region, the options and the landmarks (32 hex
    characters)."""
    parts = (body_key(source.vertices, source.faces), body_key(target.vertices, target.faces),
             hashlib.blake2b(np.packbits(region).tobytes(), digest_size=8).hexdigest(), repr(asdict(options)),
             "" if landmarks is None else landmarks.digest())
    return hashlib.blake2b("|".join(parts).encode(), digest_size=16).hexdigest()


def wrap_key(adaptable: AdaptableHairstyle, target: Character, options: WrapOptions = WrapOptions(),
             landmarks: LandmarkPairs | None = None) -> str:
    """The key of the wrap a retarget of ``adaptable`` onto ``target`` (canonical frame) makes: the
    :attr:`WrappedTarget.key` of :func:`wrap_target`, known before wrapping (a cache's key)."""
    return content_key(adaptable.source, reach_region(adaptable.source, adaptable.hair), target, options, landmarks)


def wrap_target(adaptable: AdaptableHairstyle, target: Character, options: WrapOptions = WrapOptions(),
                landmarks: LandmarkPairs | None = None) -> WrappedTarget:
    """Wrap the source body of ``adaptable`` onto ``target`` (canonical frame), over the region its hair reaches.

    Parameters
    ----------
    landmarks : LandmarkPairs, optional
        Canonical frame; those on the fitted region steer the wrap, the others are reported unused.

    Raises
    ------
    InputError
        ``wrap_failed`` when the wrapped body does not reach the target's shape (the residual is in the message);
        ``bad_landmarks`` for a landmark off its mesh (:func:`check_landmarks`).
    """
    source = adaptable.source
    region = reach_region(source, adaptable.hair)
    pairs = None
    if landmarks is not None:
        check_landmarks(landmarks, source, target)
        pairs = landmarks.pairs()
    result = wrap_body(source.vertices, source.faces, target.vertices, target.faces, region=region, landmarks=pairs,
                       options=options)
    shape = Character(result.vertices, source.faces, name=f"{target.name or 'target'} (wrapped)")
    report = wrap_report(result)
    if landmarks is not None:
        report["landmarks_unused"] = [name for name in landmarks.names if name not in result.landmark_errors]
    return WrappedTarget(shape, content_key(source, region, target, options, landmarks), report)


def check_landmarks(landmarks: LandmarkPairs, source: Character, target: Character) -> None:
    """Refuse landmarks off their mesh: each must lie within :data:`LANDMARK_OFF_SURFACE_M` of its body (canonical
    frame), or it was given in other coordinates than the mesh's file.

    Raises
    ------
    InputError
        ``bad_landmarks`` naming the farthest landmark and its distance.
    """
    for side, body, points in (("source", source, landmarks.source), ("target", target, landmarks.target)):
        distance = np.abs(MeshQuery(body.vertices, body.faces).signed_distance(points).distance)
        worst = int(np.argmax(distance))
        if distance[worst] > LANDMARK_OFF_SURFACE_M:
            raise InputError(
                f"landmark {landmarks.names[worst]!r} lies {distance[worst] * 100:.1f} cm from the {side} body "
                f"(at most {LANDMARK_OFF_SURFACE_M * 100:g} cm); give each mesh's points in its own file's "
                "coordinates (its units and axes)", "landmarks", BAD_LANDMARKS)


def landmarks_in_canonical(landmarks: LandmarkPairs, adaptable: AdaptableHairstyle, target_input: dict) -> LandmarkPairs:
    """Landmarks given in each mesh's file coordinates, in hairport's frame: the source's in the groom's axes and
    the source body's units (the hairstyle's input report; meters for a hairstyle made in hairport's frame), the
    target's in the frame :func:`~hairport.solver.inputs.canonical_target` found (``target_input``: its report)."""
    source_units = adaptable.input_report.get("units", {}).get("source", adaptable.frame.units)
    target_frame = InputFrame(target_input["units"], target_input["up"], target_input["front"])
    return landmarks.in_canonical(adaptable.frame, source_units, target_frame)


def wrap_report(result: WrapResult) -> dict:
    """The metrics' ``wrap`` section of a wrap (meters)."""
    residual = result.residual
    return {
        "residual_m": {"mean": residual.symmetric.mean, "p95": residual.symmetric.p95, "max": residual.symmetric.max},
        "coverage": residual.coverage,
        "normal_agreement": residual.agreement,
        "landmark_errors_m": dict(result.landmark_errors),
        "fitted_vertices": int(result.region.sum()),
        "iterations": result.iterations,
        "seconds": result.seconds,
    }


def onto_body(hair: Hair, points: np.ndarray, roots: np.ndarray, body: MeshQuery) -> tuple[np.ndarray, np.ndarray]:
    """Each strand moved with its root onto the body's surface.

    Parameters
    ----------
    points : (N, 3) float64
        The hairstyle's particles, placed on the wrapped shape.
    roots : (S, 3) float64
        Its roots there.
    body : MeshQuery
        The real target.

    Returns
    -------
    points : (N, 3) float64
    roots : (S, 3) float64
        On the body's surface.
    """
    landed = body.signed_distance(roots).closest
    return points + np.repeat(landed - roots, hair.counts, axis=0), landed


@dataclass(frozen=True, eq=False)
class EmbeddedWrap:
    """A wrap held on its target's surface, to be carried to the same mesh in another shape (a later frame of a
    sequence): each wrapped vertex as the face of the target it is closest to, its barycentric coordinates there,
    and its offset from that point in the face's own axes (:func:`face_axes`).

    Attributes
    ----------
    wrapped : WrappedTarget
        The wrap it was taken from.
    faces : (W,) int64
    barycentric : (W, 3) float64
    offsets : (W, 3) float64
        Along the face's first edge, across it and along its normal (m).
    """

    wrapped: WrappedTarget
    faces: np.ndarray
    barycentric: np.ndarray
    offsets: np.ndarray

    @classmethod
    def of(cls, wrapped: WrappedTarget, target: Character) -> "EmbeddedWrap":
        """``wrapped`` (a wrap onto ``target``) held on ``target``'s surface."""
        vertices = wrapped.shape.vertices
        closest = MeshQuery(target.vertices, target.faces).signed_distance(vertices)
        axes = face_axes(target.vertices, target.faces[closest.faces])
        offsets = np.einsum("nij,nj->ni", axes, vertices - closest.closest)
        barycentric = barycentric_coordinates(closest.closest, target.vertices[target.faces[closest.faces]])
        return cls(wrapped, closest.faces, barycentric, offsets)

    def on(self, target: Character) -> WrappedTarget:
        """The wrap carried to ``target`` (the mesh it was taken on, in another shape): every vertex at its place on
        the moved surface, at its offset in the moved faces' axes. Keyed by the wrap's key and the new shape; its
        report is the wrap's, with ``carried`` true."""
        on_surface = interpolate_barycentric(target.vertices, target.faces, self.faces, self.barycentric)
        axes = face_axes(target.vertices, target.faces[self.faces])
        vertices = on_surface + np.einsum("nij,ni->nj", axes, self.offsets)
        shape = Character(vertices, self.wrapped.shape.faces, name=f"{target.name or 'target'} (wrap carried)")
        key = hashlib.blake2b(f"{self.wrapped.key}|{body_key(target.vertices, target.faces)}".encode(),
                              digest_size=16).hexdigest()
        return WrappedTarget(shape, key, {**self.wrapped.report, "carried": True})


def face_axes(vertices: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """``(K, 3, 3)`` orthonormal rows per face ``corners (K, 3) int64`` of ``vertices (V, 3)``: its first edge's
    direction, the in-plane direction across it, its normal (for a face of no area, some orthonormal rows)."""
    a, b, c = (vertices[corners[:, k]] for k in range(3))
    normal = _unit(np.cross(b - a, c - a), np.array([0.0, 0.0, 1.0]))
    along = b - a - np.einsum("ij,ij->i", b - a, normal)[:, None] * normal
    least = np.eye(3)[np.argmin(np.abs(normal), axis=1)]  # the axis farthest from the unit normal: never along it
    edge = _unit(along, _unit(np.cross(normal, least), least))
    return np.stack([edge, np.cross(normal, edge), normal], axis=1)


def _unit(vectors: np.ndarray, fallback: np.ndarray) -> np.ndarray:
    """Rows of ``vectors (K, 3)`` made unit; a zero row becomes ``fallback`` (``(3,)``, or its row of ``(K, 3)``)."""
    length = np.linalg.norm(vectors, axis=1, keepdims=True)
    return np.where(length > 0, vectors / np.where(length > 0, length, 1.0), fallback)
