"""The strand hairstyle container.

Convention: a hairstyle of S strands and N particles stores all particle positions in one
array ``points (N, 3) float64`` (meters) and the strand boundaries in ``offsets (S+1,) int64``
(compressed sparse rows): strand ``s`` is ``points[offsets[s]:offsets[s+1]]``, root first.
Every strand has at least two particles. Optional per-particle attributes (``thickness``,
``color``) and any number of named per-strand or per-particle arrays (``attributes``: UVs, ids,
group ids, transparency, a file's custom primvars) travel with the points and are carried
through retargeting unchanged: a retarget changes positions only.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from hairport.solver.model.errors import InputError

MIN_PARTICLES_PER_STRAND = 2
#: a segment no longer than this (m) is degenerate: it has no direction (float32 coordinates of a
#: 10 m scene are ~1e-6 m apart, and a hair fibre is 20-180 um thick), so its two particles are
#: welded into one (:mod:`hairport.solver.model.degenerate` says what each degenerate kind becomes)
DEGENERATE_SEGMENT_M = 1e-6
#: code of the :class:`InputError` for a hairstyle with nothing to retarget
EMPTY_HAIR = "empty_hair"

#: an attribute belongs to every particle (``vertex``: one row per particle) or to every strand
VERTEX = "vertex"
STRAND = "strand"
DOMAINS = (VERTEX, STRAND)
#: what an attribute's values mean, in words every format maps to its own type names (USD's
#: ``color3f``/``texCoord2f``/``normal3f``..., Alembic's interpretations); "" for plain numbers
ROLES = ("", "color", "texcoord", "normal", "point", "vector")
#: an attribute name: a letter or underscore, then letters, digits, underscores; ``:`` separates
#: namespaces (as in USD's ``primvars:ns:name``)
ATTRIBUTE_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(:[A-Za-z_][A-Za-z0-9_]*)*")
MAX_ATTRIBUTE_NAME = 128
#: components one row of an attribute may have (a 4x4 matrix at most)
MAX_ATTRIBUTE_COMPONENTS = 16
#: attributes one hairstyle may carry (a file declaring more is refused: each costs a pass)
MAX_ATTRIBUTES = 256
#: numpy kinds an attribute may hold: booleans, signed and unsigned integers, floats
ATTRIBUTE_KINDS = "biuf"


@dataclass(frozen=True, eq=False)
class HairAttribute:
    """One named array carried beside the points.

    Attributes
    ----------
    values : (N,) or (N, k) array for a ``vertex`` attribute, (S,) or (S, k) for a ``strand`` one
        Any boolean, integer or float dtype, kept as it is (a format that cannot hold the dtype
        converts it where that is exact, else drops the attribute and says so).
    domain : str
        ``"vertex"`` or ``"strand"``.
    role : str
        One of :data:`ROLES`.
    """

    values: np.ndarray
    domain: str
    role: str = ""

    def __post_init__(self) -> None:
        values = np.ascontiguousarray(self.values)
        if values.dtype.byteorder == ">":
            values = values.astype(values.dtype.newbyteorder("="))
        object.__setattr__(self, "values", values)
        if self.domain not in DOMAINS:
            raise ValueError(f"attribute domain {self.domain!r}, expected one of {', '.join(DOMAINS)}")
        if self.role not in ROLES:
            raise ValueError(f"attribute role {self.role!r}, expected one of {', '.join(map(repr, ROLES))}")

    @property
    def components(self) -> int:
        """Values per row (1 for a scalar attribute)."""
        return 1 if self.values.ndim == 1 else int(self.values.shape[1])

    def take(self, rows: np.ndarray) -> "HairAttribute":
        """The attribute of the given rows (particles or strands, as its domain)."""
        return HairAttribute(self.values[rows], self.domain, self.role)


def attribute_problem(name: str, attribute: HairAttribute, n_particles: int, n_strands: int) -> str | None:
    """Why ``attribute`` cannot be a hairstyle's attribute ``name`` (None: it can), in words."""
    if not isinstance(name, str) or len(name) > MAX_ATTRIBUTE_NAME or not ATTRIBUTE_NAME.fullmatch(name):
        return (f"attribute name {str(name)[:MAX_ATTRIBUTE_NAME]!r} is not a name (letters, digits, underscores, "
                f"':' between namespaces, at most {MAX_ATTRIBUTE_NAME} characters)")
    values = attribute.values
    if values.dtype.kind not in ATTRIBUTE_KINDS:
        return f"attribute {name!r} holds {values.dtype} values; booleans, integers or floats only"
    rows = n_particles if attribute.domain == VERTEX else n_strands
    if values.ndim not in (1, 2) or len(values) != rows:
        return (f"{attribute.domain} attribute {name!r} has shape {values.shape}, expected ({rows:,},) or "
                f"({rows:,}, k): one row per {'particle' if attribute.domain == VERTEX else 'strand'}")
    if not 1 <= attribute.components <= MAX_ATTRIBUTE_COMPONENTS:
        return f"attribute {name!r} has {attribute.components} values per row, at most {MAX_ATTRIBUTE_COMPONENTS}"
    if values.dtype.kind == "f" and not np.isfinite(values).all():
        row = int(np.argmin(np.isfinite(values).reshape(len(values), -1).all(axis=1)))
        return f"attribute {name!r} has a non-finite value (NaN or inf) in row {row:,}"
    return None


@dataclass(frozen=True, eq=False)
class Hair:
    """A strand hairstyle in CSR layout.

    Attributes
    ----------
    points : (N, 3) float64
        Particle positions in meters, strands concatenated, root first.
    offsets : (S+1,) int64
        ``offsets[0] == 0``, ``offsets[-1] == N``, strictly increasing by at least 2.
    thickness : (N,) float64 or None
        Per-particle strand thickness in meters (from ``.hair`` files).
    color : (N, 3) float64 or None
        Per-particle RGB in [0, 1].
    attributes : mapping of str to HairAttribute
        Every other named per-strand or per-particle array, in the order read (a copy the hairstyle owns).
    """

    points: np.ndarray
    offsets: np.ndarray
    thickness: np.ndarray | None = field(default=None)
    color: np.ndarray | None = field(default=None)
    attributes: Mapping[str, HairAttribute] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "points", np.ascontiguousarray(self.points, dtype=np.float64))
        object.__setattr__(self, "offsets", np.ascontiguousarray(self.offsets, dtype=np.int64))
        validate_layout(self.points, self.offsets)
        n = len(self.points)
        if self.thickness is not None:
            thickness = np.ascontiguousarray(self.thickness, dtype=np.float64)
            if thickness.shape != (n,):
                raise InputError(f"thickness has shape {thickness.shape}, expected ({n},)")
            object.__setattr__(self, "thickness", thickness)
        if self.color is not None:
            color = np.ascontiguousarray(self.color, dtype=np.float64)
            if color.shape != (n, 3):
                raise InputError(f"color has shape {color.shape}, expected ({n}, 3)")
            object.__setattr__(self, "color", color)
        attributes = dict(self.attributes)
        if len(attributes) > MAX_ATTRIBUTES:
            raise InputError(f"{len(attributes):,} attributes, at most {MAX_ATTRIBUTES}", code="bad_attribute")
        for name, attribute in attributes.items():
            if not isinstance(attribute, HairAttribute):
                raise TypeError(f"attribute {name!r} is a {type(attribute).__name__}, expected a HairAttribute")
            problem = attribute_problem(name, attribute, n, self.n_strands)
            if problem is not None:
                raise InputError(problem, code="bad_attribute")
        object.__setattr__(self, "attributes", attributes)

    @classmethod
    def from_strands(cls, strands: list[np.ndarray]) -> "Hair":
        """Build from a list of ``(n_s, 3)`` arrays (convenience for small inputs and tests)."""
        counts = np.array([len(s) for s in strands], dtype=np.int64)
        offsets = np.concatenate([[0], np.cumsum(counts)])
        points = np.concatenate(strands) if strands else np.zeros((0, 3))
        return cls(points, offsets)

    @property
    def n_strands(self) -> int:
        return len(self.offsets) - 1

    @property
    def n_particles(self) -> int:
        return len(self.points)

    @property
    def counts(self) -> np.ndarray:
        """(S,) int64 particles per strand."""
        return np.diff(self.offsets)

    @property
    def roots(self) -> np.ndarray:
        """(S,) int64 index of each strand's root particle."""
        return self.offsets[:-1]

    @property
    def strand_of(self) -> np.ndarray:
        """(N,) int64 strand index of every particle."""
        return np.repeat(np.arange(self.n_strands, dtype=np.int64), self.counts)

    @property
    def is_root(self) -> np.ndarray:
        """(N,) bool."""
        mask = np.zeros(self.n_particles, dtype=bool)
        mask[self.roots] = True
        return mask

    @property
    def index_in_strand(self) -> np.ndarray:
        """(N,) int64 position of each particle along its strand (root = 0)."""
        return np.arange(self.n_particles, dtype=np.int64) - np.repeat(self.offsets[:-1], self.counts)

    @property
    def segments(self) -> np.ndarray:
        """(N-S, 2) int64 particle index pairs (a, a+1) of every segment, root side first."""
        start = np.ones(self.n_particles, dtype=bool)
        start[self.offsets[1:] - 1] = False  # the tip starts no segment
        a = np.flatnonzero(start)
        return np.stack([a, a + 1], axis=1)

    @cached_property
    def short_segments(self) -> np.ndarray:
        """(N,) bool: particles that start a degenerate segment (:data:`DEGENERATE_SEGMENT_M`; tips: False)."""
        return short_segments(self.points, self.offsets, DEGENERATE_SEGMENT_M)

    @cached_property
    def at_root(self) -> np.ndarray:
        """(N,) bool: the roots and the particles joined to their root by degenerate segments only (a
        repeated root point, every particle of a collapsed strand): they are the root, go where it goes
        and never move on their own (:func:`joined_to_root`)."""
        return joined_to_root(self.offsets, self.short_segments)

    @property
    def collapsed(self) -> np.ndarray:
        """(S,) bool: strands whose every segment is degenerate (all their particles at the root)."""
        return self.at_root[self.offsets[1:] - 1]

    def place_at_roots(self, points: np.ndarray) -> np.ndarray:
        """``points (N, 3)`` (a layout of this hairstyle's, changed in place and returned) with every
        :attr:`at_root` particle moved onto its strand's root."""
        follow = np.flatnonzero(self.at_root & ~self.is_root)
        if len(follow):
            points[follow] = points[self.offsets[:-1][self.strand_of[follow]]]
        return points

    def with_points(self, points: np.ndarray) -> "Hair":
        """Same layout and attributes, new positions ``(N, 3)``."""
        return Hair(points, self.offsets, self.thickness, self.color, self.attributes)

    def strand(self, s: int) -> np.ndarray:
        return self.points[self.offsets[s] : self.offsets[s + 1]]

    def subset(self, strand_ids: np.ndarray) -> "Hair":
        """The hairstyle made of the given strands, in the given order."""
        strand_ids = np.asarray(strand_ids, dtype=np.int64)
        counts = self.counts[strand_ids]
        index = particle_indices(self.offsets, strand_ids)
        offsets = np.concatenate([[0], np.cumsum(counts)])
        return Hair(
            self.points[index],
            offsets,
            None if self.thickness is None else self.thickness[index],
            None if self.color is None else self.color[index],
            {name: attribute.take(index if attribute.domain == VERTEX else strand_ids)
             for name, attribute in self.attributes.items()},
        )

    def attributes_of(self, domain: str) -> dict[str, HairAttribute]:
        """The attributes of one domain (``"vertex"`` or ``"strand"``), in order."""
        return {name: attribute for name, attribute in self.attributes.items() if attribute.domain == domain}

    def without_attributes(self) -> "Hair":
        """The same strands, thickness and color, no other attributes."""
        return Hair(self.points, self.offsets, self.thickness, self.color)


def particle_indices(offsets: np.ndarray, strand_ids: np.ndarray) -> np.ndarray:
    """Particle indices of the given strands, concatenated.

    Parameters
    ----------
    offsets : (S+1,) int64
    strand_ids : (K,) int64

    Returns
    -------
    index : (sum of counts,) int64
    """
    starts = offsets[strand_ids]
    counts = offsets[strand_ids + 1] - starts
    total = int(counts.sum())
    run_start = np.concatenate([[0], np.cumsum(counts)[:-1]])
    return np.repeat(starts - run_start, counts) + np.arange(total, dtype=np.int64)


def short_segments(points: np.ndarray, offsets: np.ndarray, min_length: float) -> np.ndarray:
    """The particles that start a segment no longer than ``min_length`` (0: of exactly equal points).

    Parameters
    ----------
    points : (N, 3) float
    offsets : (S+1,) int64
    min_length : float
        Meters, or the file's units for a hairstyle not yet in meters (0 means the same in any).

    Returns
    -------
    short : (N,) bool
        False at tips (they start no segment).
    """
    short = np.zeros(len(points), dtype=bool)
    if len(points) < 2:
        return short
    if min_length > 0:
        step = np.diff(np.asarray(points, dtype=np.float64), axis=0)
        short[:-1] = np.einsum("ij,ij->i", step, step) <= min_length * min_length
    else:  # in the file's own dtype, without a float64 copy (the readers call this on what they read)
        short[:-1] = ~(points[1:] != points[:-1]).any(axis=1)
    short[np.asarray(offsets[1:], dtype=np.int64) - 1] = False  # a tip to the next root is no segment
    return short


def joined_to_root(offsets: np.ndarray, short: np.ndarray) -> np.ndarray:
    """The roots and the particles that only short segments separate from their root.

    Parameters
    ----------
    offsets : (S+1,) int64
    short : (N,) bool
        :func:`short_segments`.

    Returns
    -------
    at_root : (N,) bool
    """
    offsets = np.asarray(offsets, dtype=np.int64)
    # count the segments of length along each strand: a particle is at its root while none came before it
    opened = np.zeros(len(short), dtype=np.int64)
    opened[1:] = ~short[:-1]
    opened[offsets[:-1]] = 0  # a root follows no segment of its strand
    seen = np.cumsum(opened)
    return seen == np.repeat(seen[offsets[:-1]], np.diff(offsets))


def validate_layout(points: np.ndarray, offsets: np.ndarray, source: str | None = None) -> None:
    """Check a CSR hairstyle: shapes, finite coordinates, strands of >= 2 particles.

    Raises
    ------
    InputError
    """
    if points.ndim != 2 or points.shape[1] != 3:
        raise InputError(f"points must have shape (N, 3), got {points.shape}", source, "bad_shape")
    if offsets.ndim != 1 or len(offsets) < 1:
        raise InputError("offsets must be a 1-D array with at least one entry", source, "bad_shape")
    if offsets[0] != 0 or offsets[-1] != len(points):
        raise InputError(
            f"offsets must start at 0 and end at the particle count {len(points)}", source, "bad_offsets"
        )
    counts = np.diff(offsets)
    if len(counts) and counts.min() < MIN_PARTICLES_PER_STRAND:
        bad = int(np.argmax(counts < MIN_PARTICLES_PER_STRAND))
        raise InputError(
            f"strand {bad} has {int(counts[bad])} particle(s); every strand needs at least "
            f"{MIN_PARTICLES_PER_STRAND}",
            source,
            "short_strand",
        )
    if not np.isfinite(points).all():
        bad = int(np.argmax(~np.isfinite(points).all(axis=1)))
        raise InputError(f"particle {bad} has a non-finite coordinate (NaN or inf)", source, "non_finite")


def require_hair(points: np.ndarray, offsets: np.ndarray, source: str | None = None, min_length: float = 0.0) -> None:
    """Refuse a hairstyle with no strand, or whose every strand has zero length.

    A strand of zero length (all its particles at one place) has no direction to keep; when
    every strand is like that there is nothing to retarget.

    Parameters
    ----------
    points : (N, 3) float
    offsets : (S+1,) int64
        Strands of at least two particles.
    source : str, optional
        The file, for the message.
    min_length : float
        Segments no longer than this have zero length (:func:`short_segments`): 0 for a file in
        its own units (exactly equal points), :data:`DEGENERATE_SEGMENT_M` in meters.

    Raises
    ------
    InputError
        ``empty_hair`` (the code is named in the message too: a user sees only the message).
    """
    if len(offsets) < 2:
        raise InputError(f"no strand of two or more points: there is no hair to retarget (code {EMPTY_HAIR})",
                         source, EMPTY_HAIR)
    short = short_segments(points, offsets, min_length)
    tips = np.zeros(len(points), dtype=bool)
    tips[np.asarray(offsets[1:], dtype=np.int64) - 1] = True
    if (short | tips).all():
        within = "at one place" if min_length <= 0 else f"within {min_length:.3g} m"
        raise InputError(
            f"every strand ({len(offsets) - 1:,}) has zero length (all its points {within}): there is no hair "
            f"to retarget (code {EMPTY_HAIR})",
            source,
            EMPTY_HAIR,
        )
