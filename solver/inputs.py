"""The canonical-frame stage: inputs in any units and axes in, hairport's frame out, and back.

Files from other tools come in meters, centimeters or millimeters, with Y, Z or X up, often
without saying which. This stage brings the source character and its groom, then each
target, into hairport's frame (meters, +Y up, the face toward +Z) before anything else runs,
and remembers the groom's frame (:class:`~hairport.solver.model.frame.InputFrame`) so that
outputs are written back in it: the head frame, the hairline split, the presets and the
previews need no knowledge of the input's conventions.

Units, in order: given (the command line's ``--units`` / ``--hair-units``, the API's
``units`` fields), stated by the file (a skeleton sidecar's ``units``, glTF is meters, a
hairport ``.npz`` records them), else inferred (:mod:`hairport.solver.body.scale`): a groom
and a body that both lack units share the unit in which their sizes are plausible; one that
lacks them takes the unit in which its roots sit on the other; a target that lacks them
takes the unit in which it has the source's size (same topology) or in which it holds the
source's head (another topology, :mod:`hairport.solver.body.target_frame`). A groom that
does not sit on its body in the chosen units is refused (``units_mismatch``, naming the
units in which it would; ``hair_off_body`` when none would); so is a target whose size
(same topology) or head (another topology) says it is in other units than those stated.

Axes: given, else inferred (:mod:`hairport.solver.body.orientation`) for the source and its
groom (which share them), and for a target by fitting it to the source: vertex by vertex
(same topology), or by placing the source's head on it (another topology; the retarget then
wraps the source body onto it, :mod:`hairport.solver.wrapping`).

:func:`canonical_source` also measures the input section of the report: the groom against
its own body (particles inside it, roots off its surface), the units and axes and how they
were found, the bounding boxes in the files' own coordinates, the groom's degenerate pieces
(:mod:`~hairport.solver.model.degenerate`: collapsed and duplicate strands, zero-length
segments, each carried through), and warnings. It refuses stray strands first, before they
spoil the inference of the units.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from hairport.solver.body.orientation import AxesGuess, infer_axes, relative_axes
from hairport.solver.body.scale import (
    BODY_EXTENT_M,
    CLEAR_FIT_SHARE,
    FIT_MAX_SHARE,
    SCALP_EXTENT_M,
    largest_extent,
    log_outside,
    relative_fits,
    root_fit_share,
    units_from_ratio,
    units_from_sizes,
)
from hairport.solver.body.skinning import derive_skin_weights
from hairport.solver.body.target_frame import CONFIDENT_RATIO, HEAD_SCALES, FrameFit, fit_target_frame
from hairport.solver.hairline.edit import HairlineEdit
from hairport.solver.mesh.collision import collision_query
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.character import Character, check_same_topology
from hairport.solver.model.degenerate import degenerate_report, require_no_stray_strands
from hairport.solver.model.errors import InputError, TopologyMismatch
from hairport.solver.model.frame import AUTO, InputFrame, character_axes_in, hair_axes_in, hair_axes_out, parse_axis
from hairport.solver.model.hair import Hair
from hairport.solver.model.units import METERS_PER_UNIT

#: roots farther than this from the source body's surface are reported as off the scalp (mm):
#: a procedural or re-exported groom has its roots within micrometres; real files were seen
#: 2-5 mm off, which the anchoring silently snaps
ROOT_OFF_SURFACE_MM = 1.0
#: a target whose size (the diagonal of its bounding box) differs from the
#: source's by more than this factor, in the units it states, is refused: characters of one
#: topology differ by less (MakeHuman child -> heavy male: 1.4)
PLAUSIBLE_SIZE_FACTOR = 3.0
#: a target of another topology whose head the source's fits closer than this (m, mean distance, at the best of
#: its tried sizes) in its stated units is read in them without trying others: the MakeHuman heads fit their
#: true frame at 3.5-7.4 mm remeshed to 20k vertices, 7.7 (body) and 8.8 mm (head) at 5k; shapes that are no head
#: at 12-21 mm (:mod:`~hairport.solver.body.target_frame`)
HEAD_FIT_M = 0.010
#: how the frame of a target of another topology is found, in the input report
OTHER_TOPOLOGY_HOW = "fitted to the source's head (another topology)"


@dataclass(frozen=True)
class SourceInputs:
    """The source character and its groom in hairport's frame, and what the stage found.

    Attributes
    ----------
    source : Character
        Canonical frame (meters, +Y up, face +Z).
    hair : Hair
        Canonical frame.
    frame : InputFrame
        The groom file's frame: outputs are written back in it.
    report : dict
        The report's ``input`` section (JSON-ready).
    warnings : tuple of str
        One line each, also in ``report["warnings"]``.
    """

    source: Character
    hair: Hair
    frame: InputFrame
    report: dict = field(default_factory=dict)
    warnings: tuple[str, ...] = ()

    def summary(self) -> str:
        """One line: the units and axes and where they came from."""
        units, axes = self.report["units"], self.report["axes"]
        return (f"input: units {units['hair']} ({units['how']}); up {axes['up']} ({axes['up_how']}), "
                f"front {axes['front']} ({axes['front_how']})")


def auto_or(value: str | None) -> str | None:
    """``None`` for an option left to inference (``None`` or ``"auto"``), else the value."""
    return None if value is None or value == AUTO else value


def canonical_source(
    source: Character,
    hair: Hair,
    *,
    source_units: str | None = None,
    hair_units: str | None = None,
    up: str | None = None,
    front: str | None = None,
    measure: bool = True,
) -> SourceInputs:
    """Bring a source character and its groom into hairport's frame.

    Parameters
    ----------
    source : Character
        In meters when ``source_units`` is given, else in the file's own (unknown) units.
    hair : Hair
        In meters when ``hair_units`` is given, else in the file's own units; in the same
        axes as ``source``.
    source_units, hair_units : str, optional
        The units the files were read in (given or stated by the file), or None to infer.
    up, front : str, optional
        The input axes that point up and to the face (``x``, ``-z``, ...), or None to infer.
    measure : bool
        Measure the groom against its body for the report (one signed-distance query of
        every particle).

    Returns
    -------
    inputs : SourceInputs

    Raises
    ------
    InputError
        ``units_mismatch`` (the groom sits on the body in other units than these),
        ``hair_off_body`` (in no units), ``bad_axis``, ``unknown_units``, ``stray_strands``
        (strands far from the rest of the groom, :mod:`~hairport.solver.model.degenerate`).
    """
    # unit-free, so in the file's own units: a stray root would decide the units inferred from sizes
    require_no_stray_strands(hair.points, hair.offsets, "hair")
    source_units, hair_units = auto_or(source_units), auto_or(hair_units)
    up = None if auto_or(up) is None else parse_axis(up, "up axis")
    front = None if auto_or(front) is None else parse_axis(front, "front axis")
    # the units and axes are inferred from the strands with a shape: a collapsed strand has no direction,
    # and a damaged file's zeros (all at the origin) spoiled the units inferred from the roots' extent
    shaped = _shaped_strands(hair)
    roots = shaped.points[shaped.roots]
    query = MeshQuery(source.vertices, source.faces)
    body_units, chosen_hair_units, units_how = _choose_units(source, roots, query, source_units, hair_units)
    body_scale = 1.0 if source_units else METERS_PER_UNIT[body_units]  # meters per loaded body unit
    hair_scale = 1.0 if hair_units else METERS_PER_UNIT[chosen_hair_units]  # meters per loaded hair unit
    file_scale = METERS_PER_UNIT[hair_units] if hair_units else 1.0  # loaded hair units per file unit
    _check_fit(query, roots, body_units, chosen_hair_units, source_units, hair_units, source.name)
    hair_units = chosen_hair_units
    in_meters = source
    if body_scale != 1.0:
        skeleton = None if source.skeleton is None else source.skeleton.scaled(body_scale)
        in_meters = Character(source.vertices * body_scale, source.faces, skeleton, source.weights, source.name)
    if in_meters.skeleton is not None and in_meters.weights is None:
        # a sidecar without weights next to a mesh of unstated units: derived now, in meters
        weights = derive_skin_weights(in_meters.vertices, in_meters.faces, in_meters.skeleton)
        in_meters = Character(in_meters.vertices, in_meters.faces, in_meters.skeleton, weights, in_meters.name)
    shaped_m = shaped.with_points(shaped.points * hair_scale) if hair_scale != 1.0 else shaped
    guess = infer_axes(in_meters, shaped_m, up, front)
    frame = InputFrame(hair_units, guess.up, guess.front)
    canonical = character_axes_in(frame, in_meters)
    canonical_hair = hair_axes_in(frame, hair, hair_scale)
    report = {
        "units": {"hair": hair_units, "source": body_units, "how": units_how},
        "axes": _axes_report(guess),
        "bounding_boxes": {"hair": _bbox(hair.points / file_scale, hair_units),
                           "source": _bbox(in_meters.vertices / METERS_PER_UNIT[body_units], body_units)},
    }
    notes = list(guess.warnings())
    size = largest_extent(canonical.vertices)
    if log_outside(size, BODY_EXTENT_M) > 0:
        notes.append(f"the source body is {size:.3g} m across in {report['units']['source']}, outside the "
                     f"{BODY_EXTENT_M[0]}-{BODY_EXTENT_M[1]} m of a head or a body; check its units")
    if measure:
        measured, measured_notes = measure_groom(canonical, canonical_hair)
        report.update(measured)
        notes += measured_notes
        report["degenerate"], degenerate_notes = degenerate_report(canonical_hair)
        notes += degenerate_notes
    report["warnings"] = notes
    return SourceInputs(canonical, canonical_hair, frame, report, tuple(notes))


def _shaped_strands(hair: Hair) -> Hair:
    """``hair`` without its collapsed strands (:attr:`~hairport.solver.model.hair.Hair.collapsed`, here in the
    file's units), or all of it when every strand is collapsed (preprocessing refuses it: ``empty_hair``)."""
    collapsed = hair.collapsed
    if not collapsed.any() or collapsed.all():
        return hair
    return hair.without_attributes().subset(np.flatnonzero(~collapsed))


def _choose_units(source: Character, roots: np.ndarray, query: MeshQuery, source_units: str | None,
                  hair_units: str | None) -> tuple[str, str, str]:
    """The body's and the hair's units, and how they were found (see the module notes).

    ``roots`` and ``query`` are in the units the files were loaded in: meters for a file with
    known units, its own units otherwise."""
    if source_units and hair_units:
        return source_units, hair_units, "given or stated by the files"
    if source_units:
        fits = relative_fits(query, roots, "m")
        best = min(fits, key=fits.get)
        return source_units, best, f"inferred for the hair: read in {best} its roots sit on the body"
    if hair_units:
        # the hair is in meters, the body in unknown units u: its roots sit on the body in u
        # when, divided by meters-per-u, they meet the surface
        fits = {units: root_fit_share(query, roots, 1.0 / scale) for units, scale in METERS_PER_UNIT.items()}
        best = min(fits, key=fits.get)
        return best, hair_units, f"inferred for the body: read in {best} the roots sit on it"
    guess = units_from_sizes(source.vertices, roots)
    return guess.units, guess.units, f"inferred from sizes: {guess.describe()}"


def _check_fit(query: MeshQuery, roots: np.ndarray, body_units: str, hair_units: str, body_stated: str | None,
               hair_stated: str | None, name: str) -> None:
    """Refuse a groom that does not sit on its body in the units chosen for both.

    Every reading of the two files is tried (each unit for each, stated or not): when the
    chosen one does not fit (:data:`FIT_MAX_SHARE`) or another fits clearly better, the error
    names the reading that fits, keeping stated units where it can, then the most plausible
    sizes.

    Parameters
    ----------
    query : MeshQuery
        Over the body as loaded: meters when ``body_stated`` (its file's units), else the
        file's own coordinates.
    roots : (S, 3) float64
        As loaded: meters when ``hair_stated``, else the hair file's own coordinates.
    """
    body_extent, scalp_extent = largest_extent(query.vertices), largest_extent(roots)
    body_loaded = METERS_PER_UNIT[body_stated] if body_stated else 1.0  # loaded units per file unit
    hair_loaded = METERS_PER_UNIT[hair_stated] if hair_stated else 1.0
    shares: dict[float, float] = {}

    def reading(pair: tuple[str, str]) -> tuple[int, float, float]:
        """(stated units changed, implausibility, fit share) with the body file read in pair[0], the hair in pair[1]."""
        body_scale = METERS_PER_UNIT[pair[0]] / body_loaded  # meters per loaded unit
        hair_scale = METERS_PER_UNIT[pair[1]] / hair_loaded
        relative = hair_scale / body_scale
        if relative not in shares:
            shares[relative] = root_fit_share(query, roots, relative)
        changed = int(bool(body_stated) and pair[0] != body_stated) + int(bool(hair_stated) and pair[1] != hair_stated)
        implausible = log_outside(body_extent * body_scale, BODY_EXTENT_M) + log_outside(
            scalp_extent * hair_scale, SCALP_EXTENT_M)
        return changed, implausible, shares[relative]

    share = reading((body_units, hair_units))[2]
    pairs = [(b, h) for b in METERS_PER_UNIT for h in METERS_PER_UNIT]
    fitting = [pair for pair in pairs if reading(pair)[2] <= CLEAR_FIT_SHARE]
    best = min(fitting, key=reading) if fitting else None
    clearly_better = best is not None and share > CLEAR_FIT_SHARE and share > 3.0 * reading(best)[2]
    if share <= FIT_MAX_SHARE and not clearly_better:
        return
    distance = share * scalp_extent * METERS_PER_UNIT[hair_units] / hair_loaded  # meters
    used = f"the hair in {hair_units} and the body in {body_units}"
    if best is not None:
        body_best, hair_best = best
        option = f"--hair-units {hair_best}" + ("" if body_best == body_units else f" --units {body_best}")
        api = f"the hairstyle's units={hair_best}" + (
            "" if body_best == body_units else f", the character's units={body_best}")
        raise InputError(
            f"the hair does not sit on the source body with {used}: its roots lie a median {distance:.3g} m from "
            f"the body's surface; with the hair in {hair_best} and the body in {body_best} they sit on it - give "
            f"those units (command line: {option}; API: {api})", name, "units_mismatch",
        )
    raise InputError(
        f"the hair does not sit on the source body: its roots lie a median {distance:.3g} m from the body's "
        f"surface with {used}, and in no other units would they sit on it; is it the groom of this character, "
        "in the same axes?", name, "hair_off_body",
    )


def _axes_report(guess: AxesGuess) -> dict:
    return {"up": guess.up, "front": guess.front, "up_how": guess.up_how, "front_how": guess.front_how,
            "up_confidence": round(guess.up_confidence, 3), "front_confidence": round(guess.front_confidence, 3)}


def _bbox(points: np.ndarray, units: str) -> dict:
    """Bounding box in a file's own coordinates and units."""
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    return {"min": np.round(points.min(axis=0), 9).tolist(), "max": np.round(points.max(axis=0), 9).tolist(),
            "units": units}


def measure_groom(source: Character, hair: Hair, query: MeshQuery | None = None) -> tuple[dict, list[str]]:
    """The groom against its own body: particles inside it, roots off its surface.

    Parameters
    ----------
    source : Character
        Canonical frame.
    hair : Hair
        Canonical frame.
    query : MeshQuery, optional
        Over ``source``; by default its collision surface
        (:func:`~hairport.solver.mesh.collision.collision_query`), whose sign is the body's
        inside at any depth, open bodies included (the test of the final penetration check).

    Returns
    -------
    measured : dict
        ``source_penetration`` (non-root particles inside the body: ``particles``,
        ``deepest_m``; those at a root, :attr:`~hairport.solver.model.hair.Hair.at_root`, are the root) and ``root_distance_m`` (roots to the body surface: ``mean``, ``max``,
        ``off_surface``: roots farther than :data:`ROOT_OFF_SURFACE_MM`, ``inside``: those of
        them inside the body).
    warnings : list of str
    """
    query = query or collision_query(source.vertices, source.faces, source.name)
    distance = query.signed_distance(hair.points).distance
    is_root = hair.is_root
    inside = (distance < 0.0) & ~hair.at_root
    root_distance = distance[is_root]
    off = np.abs(root_distance) > ROOT_OFF_SURFACE_MM * 1e-3
    deepest = float(-distance[inside].min()) if inside.any() else 0.0
    measured = {
        "source_penetration": {"particles": int(inside.sum()), "deepest_m": deepest},
        "root_distance_m": {"mean": float(np.abs(root_distance).mean()), "max": float(np.abs(root_distance).max()),
                            "off_surface": int(off.sum()), "inside": int((off & (root_distance < 0)).sum()),
                            "tolerance_mm": ROOT_OFF_SURFACE_MM},
    }
    notes = []
    if off.any():
        notes.append(
            f"{int(off.sum()):,} of {hair.n_strands:,} roots sit more than {ROOT_OFF_SURFACE_MM:g} mm off the source "
            f"body (mean {1e3 * np.abs(root_distance[off]).mean():.2f} mm, largest {1e3 * np.abs(root_distance).max():.2f}"
            " mm); each is anchored at its closest point on the body")
    if inside.any():
        notes.append(
            f"{int(inside.sum()):,} of {hair.n_particles:,} hair particles are inside the source body (deepest "
            f"{1e3 * deepest:.2f} mm); on the target they are moved out of the body")
    return measured, notes


def canonical_target(
    source: Character,
    target: Character,
    *,
    units: str | None = None,
    up: str | None = None,
    front: str | None = None,
) -> tuple[Character, dict]:
    """Bring a target character into hairport's frame, next to a canonical source.

    Of the source's topology, it takes the units in which it has the source's size and the axes
    that fit it to the source vertex by vertex; of another topology, the frame in which it holds
    the source's head (:func:`~hairport.solver.body.target_frame.fit_target_frame`). What is given
    is kept either way.

    Parameters
    ----------
    source : Character
        The source, canonical frame (e.g. ``adaptable.source``).
    target : Character
        In meters when ``units`` is given, else in the file's own units; any topology.
    units : str, optional
        The units the target was read in (given or stated by the file); None to infer them.
    up, front : str, optional
        Its up and front axes, or None to fit them.

    Returns
    -------
    target : Character
        Canonical frame.
    report : dict
        ``units``, ``up``, ``front``, how each was found and how confidently, ``topology``
        (``same`` or ``other``), the size ratio to the source, the bounding box in the file's
        coordinates and, for another topology, ``head_fit_mm`` (JSON-ready).

    Raises
    ------
    InputError
        ``units_mismatch`` when the stated units contradict the target: of the source's
        topology, it is more than :data:`PLAUSIBLE_SIZE_FACTOR` times larger or smaller than
        the source; of another, the source's head fits it clearly closer in other units
        (:func:`_check_stated_units`). ``bad_axis`` for axes that are not perpendicular.
    """
    units = auto_or(units)
    given_up = None if auto_or(up) is None else parse_axis(up, "up axis")
    given_front = None if auto_or(front) is None else parse_axis(front, "front axis")
    try:
        check_same_topology(source, target)
    except TopologyMismatch:
        frame, scale, found = _other_topology_frame(source, target, units, given_up, given_front)
    else:
        frame, scale, found = _same_topology_frame(source, target, units, given_up, given_front)
    canonical = character_axes_in(frame, target, scale)
    source_size = _size(source.vertices)
    ratio = _size(target.vertices) * scale / source_size if source_size > 0 else 1.0
    file_scale = 1.0 if units is None else METERS_PER_UNIT[frame.units]  # loaded units per file unit
    report = {"units": frame.units, "units_how": found.pop("units_how"), "up": frame.up, "front": frame.front,
              **found, "size_ratio_to_source": round(ratio, 4),
              "bounding_box": _bbox(target.vertices / file_scale, frame.units)}
    return canonical, report


def canonical_sequence(
    source: Character,
    frames: list[Character],
    *,
    units: str | None = None,
    up: str | None = None,
    front: str | None = None,
) -> tuple[list[Character], dict]:
    """Bring the frames of a target sequence into hairport's frame, all in the frame found for the first.

    One animated body keeps its units and axes from frame to frame: they are found once, on frame 0, as for a single
    target (:func:`canonical_target`), and applied to every frame, so that no frame is fitted on its own (a pose
    could then flip an axis).

    Parameters
    ----------
    source : Character
        Canonical frame.
    frames : list of Character
        Read as :func:`canonical_target`'s ``target``.
    units, up, front
        As :func:`canonical_target`'s.

    Returns
    -------
    frames : list of Character
        Canonical frame.
    report : dict
        :func:`canonical_target`'s report of frame 0.
    """
    first, report = canonical_target(source, frames[0], units=units, up=up, front=front)
    frame = InputFrame(report["units"], report["up"], report["front"])
    scale = 1.0 if units is not None else METERS_PER_UNIT[frame.units]
    return [first] + [character_axes_in(frame, body, scale) for body in frames[1:]], report


def _same_topology_frame(source: Character, target: Character, units: str | None, up: str | None,
                         front: str | None) -> tuple[InputFrame, float, dict]:
    """The frame of a target of the source's topology, meters per loaded unit, and how they were found: the units
    in which it has the source's size (``units_mismatch`` when stated ones are implausible), the axes that fit it
    to the source vertex by vertex (Kabsch)."""
    source_size, raw_size = _size(source.vertices), _size(target.vertices)
    if units is None:
        target_units = units_from_ratio(source_size / raw_size) if raw_size > 0 else "m"
        scale, units_how = METERS_PER_UNIT[target_units], "inferred: the source's size"
    else:
        target_units, scale, units_how = units, 1.0, "given or stated by the file"
    ratio = raw_size * scale / source_size if source_size > 0 else 1.0
    if not 1.0 / PLAUSIBLE_SIZE_FACTOR <= ratio <= PLAUSIBLE_SIZE_FACTOR:
        likely = units_from_ratio(METERS_PER_UNIT[target_units] * source_size / (raw_size * scale))
        raise InputError(
            f"the target is {ratio:.3g} times the size of the source (same topology) with its units {target_units}; "
            f"it looks like it is in {likely} - give its units as {likely}", target.name, "units_mismatch")
    if up is not None and front is not None:
        frame, axes_how, confidence = InputFrame(target_units, up, front), "given", 1.0
    else:
        fitted_up, fitted_front, confidence = relative_axes(source.vertices, target.vertices)
        frame = InputFrame(target_units, up or fitted_up, front or fitted_front)
        axes_how = "fitted to the source (same topology)"
    return frame, scale, {"units_how": units_how, "axes_how": axes_how, "axes_confidence": round(confidence, 3),
                          "topology": "same"}


def _other_topology_frame(source: Character, target: Character, units: str | None, up: str | None,
                          front: str | None) -> tuple[InputFrame, float, dict]:
    """The frame of a target of another topology, meters per loaded unit, and how they were found: what is given,
    the rest from the frame in which the source's head fits it best (in the file's own coordinates, so that stated
    units are checked against the others: :func:`_check_stated_units`)."""
    in_file = target if units is None else Character(target.vertices / METERS_PER_UNIT[units], target.faces,
                                                      name=target.name)
    fit = fit_target_frame(source, in_file, units, up, front)
    if units is not None and fit.score_m > HEAD_FIT_M:
        _check_stated_units(source, in_file, units, up, front, fit)
    scale = 1.0 if units is not None else METERS_PER_UNIT[fit.frame.units]
    axes_given = up is not None and front is not None
    return fit.frame, scale, {
        "units_how": "given or stated by the file" if units is not None else OTHER_TOPOLOGY_HOW,
        "axes_how": "given" if axes_given else OTHER_TOPOLOGY_HOW,
        "axes_confidence": 1.0 if axes_given else round(fit.confidence, 3),
        "topology": "other", "head_fit_mm": round(1e3 * fit.score_m, 2)}


def _check_stated_units(source: Character, in_file: Character, units: str, up: str | None, front: str | None,
                        stated: FrameFit) -> None:
    """Refuse a target of another topology whose head says it is in other units than those stated.

    Called when the source's head, at any of its tried sizes, fits the target read in its stated units no closer
    than :data:`HEAD_FIT_M`: the head is then fitted in every unit, and when another fits it at least
    :data:`~hairport.solver.body.target_frame.CONFIDENT_RATIO` times closer, the stated units are refused
    (``units_mismatch``, naming that unit). A target that is no head in any unit is left to the wrap
    (``wrap_failed``).

    Parameters
    ----------
    in_file : Character
        The target in its file's coordinates.
    stated : FrameFit
        The fit in the stated units.
    """
    best = fit_target_frame(source, in_file, None, up, front)
    if best.frame.units == units or stated.score_m < CONFIDENT_RATIO * best.score_m:
        return
    likely = best.frame.units
    raise InputError(
        f"the target's head is not a head's size in its units {units}: the source's head, at {min(HEAD_SCALES):g}-"
        f"{max(HEAD_SCALES):g} times its size, fits it {1e3 * stated.score_m:.3g} mm off on average read in {units} and {1e3 * best.score_m:.3g} "
        f"mm read in {likely} (another topology); it looks like it is in {likely} - give its units as {likely}",
        in_file.name, "units_mismatch")


def _size(vertices: np.ndarray) -> float:
    """The diagonal of the bounding box: unlike a mean over vertices, it does not depend on
    where the vertices crowd (toy characters of one topology move their rings along the body)."""
    return float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))


def hair_in_frame(frame: InputFrame, hair: Hair) -> Hair:
    """A canonical result with the groom file's axes, in meters (write it with ``units=frame.units``)."""
    return hair_axes_out(frame, hair)


def edit_in_canonical(frame: InputFrame, edit: HairlineEdit | None) -> HairlineEdit | None:
    """A hairline edit whose drawn curve is in the groom's axes, with canonical axes (presets unchanged)."""
    if edit is None or edit.curve is None or frame.is_canonical_axes:
        return edit
    return replace(edit, curve=replace(edit.curve, points=frame.axes_in(edit.curve.points)))
