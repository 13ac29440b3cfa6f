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
from hairport.solver.model.character import Character
from hairport.solver.model.degenerate import strand_lengths
from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import Hair
from hairport.solver.options import WRAP_MODES
from hairport.solver.wrap import WrapOptions, WrapResult, hair_region, wrap_body

WRAP_AUTO, WRAP_ALWAYS, WRAP_OFF = WRAP_MODES
#: the fitted region: source vertices within the longest strand's length of a hair particle, plus this margin (m)
REACH_MARGIN_M = 0.02


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


def reach_region(source: Character, hair: Hair) -> np.ndarray:
    """(V,) bool: the source vertices the hair touches or can reach (within its longest strand's length)."""
    reach = float(strand_lengths(hair.points, hair.offsets).max(initial=0.0)) + REACH_MARGIN_M
    return hair_region(source.vertices, source.faces, hair.points, reach)


def content_key(source: Character, region: np.ndarray, target: Character, options: WrapOptions) -> str:
    """The content digest of a wrap: both bodies, the fitted region and the options (32 hex characters)."""
    parts = (body_key(source.vertices, source.faces), body_key(target.vertices, target.faces),
             hashlib.blake2b(np.packbits(region).tobytes(), digest_size=8).hexdigest(), repr(asdict(options)))
    return hashlib.blake2b("|".join(parts).encode(), digest_size=16).hexdigest()


def wrap_key(adaptable: AdaptableHairstyle, target: Character, options: WrapOptions = WrapOptions()) -> str:
    """The key of the wrap a retarget of ``adaptable`` onto ``target`` (canonical frame) makes: the
    :attr:`WrappedTarget.key` of :func:`wrap_target`, known before wrapping (a cache's key)."""
    return content_key(adaptable.source, reach_region(adaptable.source, adaptable.hair), target, options)


def wrap_target(adaptable: AdaptableHairstyle, target: Character, options: WrapOptions = WrapOptions()) -> WrappedTarget:
    """Wrap the source body of ``adaptable`` onto ``target`` (canonical frame), over the region its hair reaches.

    Raises
    ------
    InputError
        ``wrap_failed`` when the wrapped body does not reach the target's shape (the residual is in the message).
    """
    source = adaptable.source
    region = reach_region(source, adaptable.hair)
    result = wrap_body(source.vertices, source.faces, target.vertices, target.faces, region=region, options=options)
    shape = Character(result.vertices, source.faces, name=f"{target.name or 'target'} (wrapped)")
    return WrappedTarget(shape, content_key(source, region, target, options), wrap_report(result))


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
