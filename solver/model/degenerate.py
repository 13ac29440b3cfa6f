"""Degenerate pieces of otherwise good grooms: what each kind is, and what hairport does with it.

Real grooms carry pieces without a shape: a hair exported as its scalp position only, repeated
points, a strand copied twice, a truncated file whose middle reads as zeros, a stray curve far
from the head. Each kind is decided once, here and in the modules named; the output keeps the
input's strand layout (attributes are carried per strand and per particle), so nothing is dropped:

* **Zero-length segment** (no longer than :data:`~.hair.DEGENERATE_SEGMENT_M`): it has no
  direction, so Eq. 7 has none to keep, and Eq. 7's term divides by the length, its Hessian by the
  length squared: at zero length the block came out NaN (no normal to a zero direction) and the
  strand-banded Hessian "not positive definite", the ``internal`` error of a penetration test. Its
  two particles are *welded*: a stiff spring of that length scale replaces the term
  (:mod:`hairport.solver.adaptation.problem.energies`), so the segment stays of zero length and the solve
  stays well conditioned. Carried, with a warning (count, strands).
* **Collapsed strand** (every segment of zero length), and the zero-length run at a strand's
  start (a repeated root point): welded to the root, these particles *are* the root
  (:attr:`.hair.Hair.at_root`): they are placed where the root goes, the solvers keep them fixed
  like roots, and no clearance is asked of them (the root sits on the skin). Carried, with a
  warning (count, first strands); a groom of nothing else is refused (``empty_hair``).
* **Duplicate strand** (every point equal to an earlier strand's): Eq. 9 normalises the inverse
  distances after clamping them, so a twin at distance 0 takes its particle's whole weight: a
  bounded row, no singular system, and the twins stay together (measured on 300 toy strands: the
  twins ended within 0.8 mm of each other, the other strands moved as for any strand added, 0-2
  mm). Carried, with a warning.
* **Strand of two points**: one segment, an ordinary strand; carried without a warning.
* **Far strand** (a particle farther than two groom sizes from every other strand, :func:`groom_size`):
  its Eq. 10 rows held offsets of metres and pulled the strands they named (a copy moved 1.5 m off the
  toy head moved its neighbours by 11 cm); it has no neighbours (:mod:`hairport.solver.adaptation.source.neighbours`)
  and is retargeted by its own anchors and shape. Carried, with the input report's warning of roots off
  the body when its root is. Closer strands are neighbours like any (a copy 0.5 m away moved its
  neighbours by up to 6 cm: a groom decides where its strands are).
* **Stray strand** (a particle farther from the groom's roots than :data:`STRAY_SIZES` times the
  groom's size): refused (``stray_strands``, naming how many and the first ones) before anything
  else, at upload too. Anchoring a particle that far from the body means nothing, near float32's
  limit a strand's shape rounds away (1e37 plus a few centimetres is 1e37), and a stray root spoils
  the inference of the groom's units (the roots' extent). The test is unit-free (sizes of the groom itself), so it
  gives the same answer in the file's units and in meters.

Strands at the origin (zeros read from a damaged file) are one of the kinds above: collapsed when
all their points are there, far or stray when far from the rest, else ordinary strands that the solve
keeps out of the body. The units and axes of a groom are inferred from its strands with a length
(:mod:`hairport.solver.inputs`).
"""

from __future__ import annotations

import numpy as np

from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import Hair, particle_indices

#: code of the :class:`InputError` for a groom with strands far from the rest of it
STRAY_STRANDS = "stray_strands"
#: a strand is stray when a particle lies farther than this many groom sizes from the roots' centre;
#: the size is the roots' median distance to their centre plus the median strand length (about 0.4 m
#: on a head of long hair, so 20 m; no hair reaches more than a few sizes)
STRAY_SIZES = 50.0
#: strand indices a message or report names (the first ones)
NAMED_STRANDS = 5
#: particles measured at a time (bounds the float64 temporaries of a file's tens of millions to ~25 MB)
CHUNK_PARTICLES = 1 << 20


def named(indices: np.ndarray) -> str:
    """``"3, 17, 40"`` or ``"3, 17, 40, ..."``: the first :data:`NAMED_STRANDS` of ``indices (K,)``."""
    shown = ", ".join(f"{int(i):,}" for i in indices[:NAMED_STRANDS])
    return shown + (", ..." if len(indices) > NAMED_STRANDS else "")


def strand_lengths(points: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(S,) float64: each strand's length (in the units of ``points (N, 3)``).

    Summed strand by strand, not as differences of one running sum: a strand far away (a stray
    one at 1e37) would swallow the lengths of every strand after it."""
    offsets = np.asarray(offsets, dtype=np.int64)
    length = np.zeros(len(points))
    for start in range(0, len(points) - 1, CHUNK_PARTICLES):
        stop = min(start + CHUNK_PARTICLES, len(points) - 1)
        step = np.diff(np.asarray(points[start:stop + 1], dtype=np.float64), axis=0)
        length[start:stop] = np.sqrt(np.einsum("ij,ij->i", step, step))
    length[offsets[1:] - 1] = 0.0  # a tip to the next root is no segment
    return np.add.reduceat(length, offsets[:-1]) if len(offsets) > 1 else np.zeros(0)


def distances_to(points: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """(N,) float64: each of ``points (N, 3)`` to ``centre (3,)``, a block at a time."""
    distance = np.empty(len(points))
    for start in range(0, len(points), CHUNK_PARTICLES):
        block = np.asarray(points[start:start + CHUNK_PARTICLES], dtype=np.float64) - centre
        distance[start:start + CHUNK_PARTICLES] = np.sqrt(np.einsum("ij,ij->i", block, block))
    return distance


def groom_size(points: np.ndarray, offsets: np.ndarray) -> tuple[float, np.ndarray]:
    """The groom's size: its roots' median distance to their centre (their per-axis median) plus its
    median strand length (of the strands with a length), unit-free like the groom, and that centre.

    Medians hold while fewer than half the strands are stray; 0 when no strand has a length and every
    root is at one place.

    Parameters
    ----------
    points : (N, 3) float
    offsets : (S+1,) int64
        At least one strand.

    Returns
    -------
    size : float
    centre : (3,) float64
    """
    offsets = np.asarray(offsets, dtype=np.int64)
    roots = np.asarray(points[offsets[:-1]], dtype=np.float64)
    centre = np.median(roots, axis=0)
    spread = float(np.median(np.linalg.norm(roots - centre, axis=1)))
    lengths = strand_lengths(points, offsets)
    typical = float(np.median(lengths[lengths > 0])) if (lengths > 0).any() else 0.0
    return spread + typical, centre


def stray_strands(points: np.ndarray, offsets: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The strands that reach far beyond the rest of the groom (unit-free: see :data:`STRAY_SIZES`).

    Parameters
    ----------
    points : (N, 3) float
        Finite, in any units.
    offsets : (S+1,) int64

    Returns
    -------
    stray : (S,) bool
    reach : (S,) float64
        Each strand's farthest particle from the roots' centre, in groom sizes (:func:`groom_size`).
    size : float
        The groom's size in the units of ``points`` (0: none; nothing is then stray).
    """
    offsets = np.asarray(offsets, dtype=np.int64)
    n_strands = len(offsets) - 1
    if n_strands < 1:
        return np.zeros(0, dtype=bool), np.zeros(0), 0.0
    size, centre = groom_size(points, offsets)
    if not size > 0:
        return np.zeros(n_strands, dtype=bool), np.zeros(n_strands), 0.0
    reach = np.maximum.reduceat(distances_to(points, centre), offsets[:-1]) / size
    return reach > STRAY_SIZES, reach, size


def require_no_stray_strands(points: np.ndarray, offsets: np.ndarray, source: str | None = None) -> None:
    """Refuse a groom with stray strands (:func:`stray_strands`).

    Raises
    ------
    InputError
        ``stray_strands``, naming how many and the first ones.
    """
    stray, reach, _ = stray_strands(points, offsets)
    if stray.any():
        which = np.flatnonzero(stray)
        raise InputError(
            f"{len(which):,} of {len(stray):,} strands lie far from the rest of the groom (strand(s) {named(which)}: "
            f"up to {reach[which].max():.3g} times the groom's size from its roots, at most {STRAY_SIZES:g} is hair); "
            f"they look like stray geometry (a broken export or a damaged file): remove them (code {STRAY_STRANDS})",
            source, STRAY_STRANDS,
        )


def duplicate_strands(points: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """The strands whose every point equals an earlier strand's (same count, same order).

    Candidates share their particle count, root and tip (one sort of ``(S, 7)`` keys); only those
    are compared point by point.

    Parameters
    ----------
    points : (N, 3) float64
    offsets : (S+1,) int64

    Returns
    -------
    duplicate : (S,) bool
        False for the first strand of each group of equal ones.
    """
    offsets = np.asarray(offsets, dtype=np.int64)
    n_strands = len(offsets) - 1
    duplicate = np.zeros(n_strands, dtype=bool)
    if n_strands < 2:
        return duplicate
    counts = np.diff(offsets)
    key = np.column_stack([counts.astype(np.float64), points[offsets[:-1]], points[offsets[1:] - 1]])
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    earlier = first[np.ravel(inverse)]
    candidates = np.flatnonzero(earlier != np.arange(n_strands))
    if len(candidates) == 0:
        return duplicate
    equal = (points[particle_indices(offsets, candidates)] == points[particle_indices(offsets, earlier[candidates])])
    starts = np.concatenate([[0], np.cumsum(counts[candidates])[:-1]])
    duplicate[candidates] = np.logical_and.reduceat(equal.all(axis=1), starts)
    return duplicate


def degenerate_report(hair: Hair) -> tuple[dict, list[str]]:
    """The degenerate pieces of a hairstyle (in meters) for the input report, and its warnings.

    Returns
    -------
    report : dict
        ``collapsed_strands``, ``duplicate_strands`` (``count``, ``strands``: the first indices) and
        ``zero_length_segments`` (``count`` outside collapsed strands, ``strand_count``, ``strands``).
    warnings : list of str
        One line per kind present.
    """
    collapsed = np.flatnonzero(hair.collapsed)
    short = hair.short_segments & ~np.repeat(hair.collapsed, hair.counts)
    short_strands = np.unique(hair.strand_of[short])
    duplicates = np.flatnonzero(duplicate_strands(hair.points, hair.offsets))
    report = {
        "collapsed_strands": {"count": len(collapsed), "strands": collapsed[:NAMED_STRANDS].tolist()},
        "zero_length_segments": {"count": int(short.sum()), "strand_count": len(short_strands),
                                 "strands": short_strands[:NAMED_STRANDS].tolist()},
        "duplicate_strands": {"count": len(duplicates), "strands": duplicates[:NAMED_STRANDS].tolist()},
    }
    notes = []
    if len(collapsed):
        notes.append(f"{len(collapsed):,} of {hair.n_strands:,} strands have zero length (all their points at one "
                     f"place: strand(s) {named(collapsed)}); each stays at its root, moved to the target")
    if len(short_strands):
        notes.append(f"{int(short.sum()):,} segment(s) of zero length (repeated points) in {len(short_strands):,} "
                     f"strand(s) ({named(short_strands)}); each keeps zero length (its two points move as one)")
    if len(duplicates):
        notes.append(f"{len(duplicates):,} strand(s) repeat an earlier strand point for point ({named(duplicates)}); "
                     "they are retargeted like the rest and stay together")
    return report, notes
