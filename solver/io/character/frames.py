"""The frames of a target sequence: several mesh files (one body each), or one animated USD stage.

* **Several files** (``.obj``, ``.ply``, ``.glb``/``.gltf``, ``.usd*``), numbered 0, 1, ... in the order given: a morph
  sweep exported frame by frame. Each is read as a single target is (its skeleton sidecar, its glTF skin), so
  every frame has its own rig or none; they must state one unit (or none).
* **One USD stage whose mesh points are time-sampled**, its frames picked by time code: the mesh is read at each
  through its world transform at that time, without a skin (the bind pose does not follow the points: each frame's
  skeleton is transferred from the source, as for any target without a rig).
* **One glTF mesh with morph targets** (:mod:`.gltf.morphs`): its morph weights animated in the file (frame ``f`` at
  ``f / 24`` seconds), or given as a list of weights per frame (numbered 0, 1, ...); without a skin either.
* **One Alembic animated mesh** (:mod:`.alembic`): its sampled positions at each frame (frame ``f`` at ``f / 24``
  seconds), no unit recorded (inferred, or ``units``).

UsdSkel animations and blend shapes, and meshes of other formats, are refused with ``not_animated``, naming what is
read instead.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hairport.solver.io.character.alembic import read_alembic_frames
from hairport.solver.io.character.gltf import READERS as GLTF_READERS
from hairport.solver.io.character.gltf.morphs import read_morph_frames
from hairport.solver.io.character.load import MESH_READERS, read_character
from hairport.solver.io.character.mesh_file import (
    DEFAULT_MAX_FACES,
    DEFAULT_MAX_FILE_BYTES,
    DEFAULT_MAX_VERTICES,
    check_file,
    check_mesh_arrays,
)
from hairport.solver.io.character.usd import READERS as USD_READERS
from hairport.solver.io.character.usd import read_usd_frames
from hairport.solver.io.external import ALLOW_EXTERNAL_FILES
from hairport.solver.io.hair.common import FRAMES_PER_SECOND
from hairport.solver.model.character import Character
from hairport.solver.model.errors import PARSER_FAILURES, InputError, parser_failure
from hairport.solver.model.frame_range import MAX_FRAMES, FrameRange
from hairport.solver.model.json_input import parse_json
from hairport.solver.model.units import unit_scale


@dataclass(frozen=True, eq=False)
class TargetFrames:
    """The frames of a target sequence as read.

    Attributes
    ----------
    characters : list of Character
        In meters when the units are known, else in the files' coordinates.
    times : list of float
        Each frame's number: its index among several files, its time code in a stage.
    units : str or None
        The units the files state (None: none does).
    frames_per_second : float
        A stage's time codes per second; :data:`FRAMES_PER_SECOND` for several files.
    """

    characters: list[Character]
    times: list[float]
    units: str | None
    frames_per_second: float = FRAMES_PER_SECOND


#: an Alembic archive's extension: read as a sequence's frames only (no still character is read from one)
ALEMBIC_EXTENSION = ".abc"
#: the largest file of morph weights read (bytes): 10,000 frames of 100 targets in JSON are ~8 MB
MAX_MORPH_WEIGHTS_BYTES = 16 * 2**20


#: most vertices over all frames of one sequence (their positions are held at once: ~1.2 GB)
MAX_SEQUENCE_VERTICES = 50_000_000


def read_character_frames(
    mesh_paths: Sequence[str | os.PathLike],
    frames: FrameRange | None = None,
    *,
    units: str | None = None,
    max_vertices: int = DEFAULT_MAX_VERTICES,
    max_faces: int = DEFAULT_MAX_FACES,
    max_bytes: int = DEFAULT_MAX_FILE_BYTES,
    mesh_name: str | None = None,
    allow_external_files: bool = ALLOW_EXTERNAL_FILES,
    morph_weights: np.ndarray | None = None,
) -> TargetFrames:
    """Read the frames of a target sequence (module notes).

    Parameters
    ----------
    mesh_paths : sequence of path
        Several mesh files, or one animated USD stage.
    frames : FrameRange, optional
        Which frames: indices into several files (all by default), time codes of a stage (needed).
    units : str, optional
        The meshes' units, as :func:`~hairport.solver.io.character.load.read_character`'s.
    morph_weights : (F, T) float64, optional
        One glTF mesh's morph-target weights of each frame (frames numbered 0, 1, ...), instead of its animation.
    max_vertices, max_faces, max_bytes, mesh_name, allow_external_files
        As :func:`~hairport.solver.io.character.load.read_character`'s, per frame.

    Returns
    -------
    frames : TargetFrames
    """
    paths = [Path(path) for path in mesh_paths]
    if not paths:
        raise InputError("no target meshes given", "target", "bad_frames")
    limits = {"max_vertices": max_vertices, "max_faces": max_faces, "max_bytes": max_bytes, "mesh_name": mesh_name,
              "allow_external_files": allow_external_files}
    if morph_weights is not None:
        return _morph_frames(paths, frames, units, limits, morph_weights)
    if len(paths) == 1:
        if frames is None:
            raise InputError("one target file is one body: give frames (START:END[:STEP]) to read an animated stage",
                             str(paths[0]), "bad_frames")
        if paths[0].suffix.lower() in GLTF_READERS:
            return _morph_frames(paths, frames, units, limits, None)
        if paths[0].suffix.lower() == ALEMBIC_EXTENSION:
            return _alembic_frames(paths[0], frames, units, limits)
        return _stage_frames(paths[0], frames, units, limits)
    picked = frames.pick(len(paths)) if frames is not None else range(len(paths))
    characters, stated, total = [], set(), 0
    for index in picked:
        character, found = read_character(paths[index], units=units, **limits)
        characters.append(character)
        stated.add(found)
        total += character.n_vertices
        check_total_vertices(total)
    if len(stated) > 1:
        raise InputError(f"the target meshes state different units ({', '.join(sorted(map(str, stated)))}): give "
                         "their units", str(paths[0]), "units_mismatch")
    return TargetFrames(characters, [float(index) for index in picked], stated.pop())


def _stage_frames(path: Path, frames: FrameRange, units: str | None, limits: dict) -> TargetFrames:
    source = str(path)
    check_file(path, limits["max_bytes"])
    suffix = path.suffix.lower()
    if suffix not in USD_READERS:
        known = f"a {suffix} file holds one body" if suffix in MESH_READERS else f"{suffix!r} is no mesh format"
        raise InputError(f"{path.name} is not animated ({known}): give one mesh file per frame, a USD stage with "
                         "time-sampled mesh points, a glTF mesh with morph targets or an Alembic animated mesh", source,
                         "not_animated")
    times = [float(t) for t in frames.times()]
    try:
        meshes, frames_per_second = read_usd_frames(path, times, max_vertices=limits["max_vertices"],
                                                    max_faces=limits["max_faces"], mesh_name=limits["mesh_name"],
                                                    allow_external_files=limits["allow_external_files"])
    except PARSER_FAILURES as error:
        raise parser_failure(error, source) from None
    mesh_units = units if units is not None else meshes[0].units
    scale = unit_scale(mesh_units or "m")
    return TargetFrames(_characters(meshes, times, path, scale, limits), times, mesh_units, frames_per_second)


def _morph_frames(paths: list[Path], frames: FrameRange | None, units: str | None, limits: dict,
                  weights: np.ndarray | None) -> TargetFrames:
    """One glTF mesh's frames: by its animation at ``frames`` (24 a second), or by the rows of ``weights``."""
    if len(paths) != 1 or paths[0].suffix.lower() not in GLTF_READERS:
        raise InputError("morph weights apply to one glTF file (.glb, .gltf)", str(paths[0]), "bad_frames")
    path = paths[0]
    check_file(path, limits["max_bytes"])
    if weights is not None:
        weights = _checked_weights(weights, str(path))
        picked = frames.pick(len(weights)) if frames is not None else np.arange(len(weights))
        times, weights = [float(index) for index in picked], weights[picked]
        kwargs = {"weights": weights}
    else:
        times = [float(t) for t in frames.times()]
        kwargs = {"times_s": np.array(times) / FRAMES_PER_SECOND}
    meshes = read_morph_frames(path, max_vertices=limits["max_vertices"], max_faces=limits["max_faces"],
                               mesh_name=limits["mesh_name"], allow_external_files=limits["allow_external_files"],
                               **kwargs)
    scale = unit_scale(units or meshes[0].units)
    return TargetFrames(_characters(meshes, times, path, scale, limits), times, units or meshes[0].units)


def read_morph_weights(path: str | os.PathLike) -> np.ndarray:
    """The morph-target weights of each frame from a JSON file: a list of lists of numbers, one list per frame and one
    number per morph target (``[[0, 0], [0.1, 0], ...]``).

    Returns
    -------
    weights : (F, T) float64

    Raises
    ------
    InputError
        ``too_large`` above :data:`MAX_MORPH_WEIGHTS_BYTES`, ``bad_json``, ``bad_frames`` for another shape or a
        non-finite number.
    """
    source = os.fspath(path)
    check_file(Path(source), MAX_MORPH_WEIGHTS_BYTES)
    with open(source, "rb") as handle:
        document = parse_json(handle.read(), source, "bad_json", "the morph weights")
    return _checked_weights(document, source)


def _alembic_frames(path: Path, frames: FrameRange, units: str | None, limits: dict) -> TargetFrames:
    """One Alembic animated mesh at ``frames`` (24 a second)."""
    check_file(path, limits["max_bytes"])
    times = [float(t) for t in frames.times()]
    try:
        meshes = read_alembic_frames(path, [t / FRAMES_PER_SECOND for t in times], max_vertices=limits["max_vertices"],
                                     max_faces=limits["max_faces"], mesh_name=limits["mesh_name"],
                                     allow_external_files=limits["allow_external_files"])
    except PARSER_FAILURES as error:
        raise parser_failure(error, str(path)) from None
    scale = unit_scale(units or "m")
    return TargetFrames(_characters(meshes, times, path, scale, limits), times, units)


def _checked_weights(weights, source: str) -> np.ndarray:
    try:
        weights = np.asarray(weights, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError("morph weights must be a list of lists of numbers, one list per frame", source,
                         "bad_frames") from None
    if weights.ndim != 2 or len(weights) == 0 or len(weights) > MAX_FRAMES or not np.isfinite(weights).all():
        raise InputError(f"morph weights must be 1 to {MAX_FRAMES:,} lists of finite numbers of one length, one a "
                         f"frame; got shape {weights.shape}", source, "bad_frames")
    return weights


def _characters(meshes: list, times: list[float], path: Path, scale: float, limits: dict) -> list[Character]:
    """One animated file's frames as characters (``scale`` meters per file unit), each checked as a mesh, and all of
    them against :data:`MAX_SEQUENCE_VERTICES`; named ``<file>@<frame>``."""
    check_total_vertices(sum(len(mesh.vertices) for mesh in meshes))
    characters = []
    for mesh, time in zip(meshes, times, strict=True):
        check_mesh_arrays(mesh.vertices, mesh.faces, str(path), limits["max_vertices"], limits["max_faces"])
        characters.append(Character(mesh.vertices * scale, mesh.faces, name=f"{path.name}@{time:g}"))
    return characters


def check_total_vertices(total: int) -> None:
    """Refuse (``too_large``) frames holding ``total`` vertices in all, above :data:`MAX_SEQUENCE_VERTICES` (every
    frame's mesh is held at once)."""
    if total > MAX_SEQUENCE_VERTICES:
        raise InputError(f"the sequence's frames hold {total:,} vertices in all, more than the {MAX_SEQUENCE_VERTICES:,} "
                         "one sequence may hold: pick fewer frames", "frames", "too_large")
