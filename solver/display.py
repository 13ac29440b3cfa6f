"""What a browser draws: a job's scene (body, strands, particles inside the body and segments through it,
hairline), decimated and packed for the dashboard's WebGL viewer.

A job's run saves its *scene* once (:func:`scene_arrays`, :func:`save_scene`): the target body and the
result in hairport's frame (meters, +Y up, face toward +Z) as float32, which particles are inside the
body and which start a segment through it (bit-packed; a scene saved before the second was kept has
none), the strands' colours, the target's current front hairline and each preset's edit of
it, and the rotation that takes hairport's frame to the groom file's axes (a drawn hairline is sent in
the groom's axes, as ``hairport hairline`` writes it). A wrapped target (another topology, or ``options.wrap``
always) adds the source body wrapped onto it (:data:`WRAPPED_ARRAYS`; a scene without them had no wrap, as one
without ``color`` has no colours). A request then draws a *decimation* of it (:func:`plan_display`,
:func:`decimate`): an evenly spread subset of strands, each with every ``stride``-th particle and always its
root and tip, so that a 10^6-particle groom arrives as a few megabytes and draws at an interactive frame rate
(the budget: ``bench/dashboard.py``).

The wire format (:func:`encode`, ``application/vnd.hairport.display``) is one JSON header and raw
little-endian arrays: the ASCII magic ``HPD1``, the header's byte length (uint32), the header
(``{"arrays": [{"name", "dtype", "shape", "offset"}], ...}``, offsets from the start of the
payload), then each array at an 8-byte aligned offset. A browser reads it with typed-array views.
"""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path

import numpy as np

from hairport.solver.model.errors import InputError
from hairport.solver.model.frame import AXIS_VECTORS, parse_axis

MAGIC = b"HPD1"
MEDIA_TYPE = "application/vnd.hairport.display"
#: vertices a decimated groom aims at unless the request sets strands or stride (bench/dashboard.py, 2026-11-25:
#: the most that Chromium's software WebGL on 2 cores still draws in under 200 ms a frame, 5 frames a second while
#: orbiting (200,000 took 330 ms); 1.3 MB on the wire. A GPU draws 10^6 smoothly: the page offers more)
DEFAULT_DISPLAY_VERTICES = 100_000
#: most vertices one display request may ask for (12 B each, plus 1 B of inside flag and 3 B of colour)
MAX_DISPLAY_VERTICES = 2_000_000
#: fewest strands the automatic plan keeps before it starts dropping particles instead (a few
#: thousand strands show a groom's silhouette; fewer look sparse)
MIN_AUTO_STRANDS = 2_000
#: largest point stride a request may ask for
MAX_STRIDE = 1_000
#: the arrays every scene holds (and the optional ``color``, presets' hairlines and :data:`WRAPPED_ARRAYS`)
SCENE_ARRAYS = ("points", "offsets", "inside", "body_vertices", "body_faces", "groom_rotation",
                "hairline_points", "hairline_turning")
#: the optional wrapped body of a target of another topology: the source's mesh in the target's shape
WRAPPED_ARRAYS = ("wrapped_vertices", "wrapped_faces")
PRESET_ARRAY = "preset_{}"
ALIGNMENT = 8
_WIRE_DTYPES = {np.dtype(np.float32): "float32", np.dtype(np.uint32): "uint32", np.dtype(np.uint8): "uint8",
                np.dtype(np.int32): "int32"}


def vertices_per_strand(lengths: np.ndarray, stride: int) -> np.ndarray:
    """(K,) int64: particles drawn of strands of ``lengths`` (each >= 2) at ``stride``: every stride-th
    from the root, and the tip."""
    return (np.asarray(lengths, dtype=np.int64) - 2) // stride + 2


def even_strands(n_strands: int, count: int) -> np.ndarray:
    """(min(count, n_strands),) int64: strand indices spread evenly over ``0..n_strands-1`` (strands lie in
    scalp order in every groom we read, so an even spread covers the whole head)."""
    count = min(int(count), n_strands)
    if count <= 0:
        return np.zeros(0, dtype=np.int64)
    return np.unique(np.round(np.linspace(0, n_strands - 1, count)).astype(np.int64))


def plan_display(offsets: np.ndarray, max_vertices: int = DEFAULT_DISPLAY_VERTICES, strands: int | None = None,
                 stride: int | None = None) -> tuple[np.ndarray, int]:
    """Which strands and which stride to draw.

    Parameters
    ----------
    offsets : (S+1,) int64
        The groom's CSR strand offsets.
    max_vertices : int
        The vertex budget when ``strands`` or ``stride`` is left to the plan.
    strands, stride : int or None
        Asked for by the request; the plan fills in the other (both given: exactly those).

    Returns
    -------
    strand_ids : (K,) int64
    stride : int
    """
    lengths = np.diff(np.asarray(offsets, dtype=np.int64))
    n_strands = len(lengths)
    if stride is not None and not 1 <= stride <= MAX_STRIDE:
        raise InputError(f"stride {stride} is outside 1-{MAX_STRIDE}", code="bad_display")
    if strands is not None and strands < 1:
        raise InputError(f"strands {strands} must be at least 1", code="bad_display")
    if not 1 <= max_vertices <= MAX_DISPLAY_VERTICES:
        raise InputError(f"a display budget of {max_vertices} vertices is outside 1-{MAX_DISPLAY_VERTICES:,}",
                         code="bad_display")
    if n_strands == 0:
        return np.zeros(0, dtype=np.int64), stride or 1
    mean_lengths = float(lengths.mean())

    def strands_fitting(step: int) -> int:
        return max(1, int(max_vertices // float(vertices_per_strand(lengths, step).mean())))

    if stride is None:
        wanted = n_strands if strands is None else min(strands, n_strands)
        floor = wanted if strands is not None else min(wanted, MIN_AUTO_STRANDS)
        per_strand_room = max_vertices / floor - 2  # particles past the root a strand may draw
        stride = (1 if mean_lengths <= 2 else int(np.clip(np.ceil((mean_lengths - 2) / per_strand_room), 1, MAX_STRIDE))
                  if per_strand_room > 0 else int(np.clip(mean_lengths - 1, 1, MAX_STRIDE)))
    count = min(n_strands, strands if strands is not None else strands_fitting(stride))
    strand_ids = even_strands(n_strands, count)
    drawn = int(vertices_per_strand(lengths[strand_ids], stride).sum())
    if drawn > MAX_DISPLAY_VERTICES:
        raise InputError(f"{count} strands at stride {stride} are {drawn:,} vertices; at most "
                         f"{MAX_DISPLAY_VERTICES:,} are drawn (fewer strands or a larger stride)", code="bad_display")
    return strand_ids, int(stride)


def decimate(offsets: np.ndarray, strand_ids: np.ndarray, stride: int) -> tuple[np.ndarray, np.ndarray]:
    """The particles drawn of strands ``strand_ids`` at ``stride``.

    Parameters
    ----------
    offsets : (S+1,) int64
    strand_ids : (K,) int64
    stride : int

    Returns
    -------
    particles : (M,) int64
        Indices into the groom's particles, strand by strand, root to tip.
    starts : (K+1,) int64
        Where each drawn strand starts in ``particles``.
    """
    offsets = np.asarray(offsets, dtype=np.int64)
    strand_ids = np.asarray(strand_ids, dtype=np.int64)
    lengths = offsets[strand_ids + 1] - offsets[strand_ids]
    counts = vertices_per_strand(lengths, stride)
    starts = np.zeros(len(strand_ids) + 1, dtype=np.int64)
    np.cumsum(counts, out=starts[1:])
    local = np.arange(starts[-1], dtype=np.int64) - np.repeat(starts[:-1], counts)
    along = np.minimum(local * stride, np.repeat(lengths - 1, counts))
    return np.repeat(offsets[strand_ids], counts) + along, starts


def encode(header: dict, arrays: dict[str, np.ndarray]) -> bytes:
    """The wire format (module docstring): ``header`` plus an ``arrays`` table, then the arrays."""
    table, blobs, position = [], [], 0
    for name, array in arrays.items():
        array = np.ascontiguousarray(array)
        if array.dtype not in _WIRE_DTYPES:
            raise ValueError(f"array {name} has dtype {array.dtype}, not one the display format carries")
        table.append({"name": name, "dtype": _WIRE_DTYPES[array.dtype], "shape": list(array.shape),
                      "offset": position})
        data = array.astype(array.dtype.newbyteorder("<"), copy=False).tobytes()
        blobs.append(data + b"\0" * (-len(data) % ALIGNMENT))
        position += len(blobs[-1])
    text = json.dumps({**header, "arrays": table}, separators=(",", ":")).encode()
    text += b" " * (-(len(text) + len(MAGIC) + 4) % ALIGNMENT)
    return b"".join([MAGIC, np.uint32(len(text)).astype("<u4").tobytes(), text, *blobs])


def decode(payload: bytes) -> tuple[dict, dict[str, np.ndarray]]:
    """The header and arrays of :func:`encode`'s output (tests and benches read it back)."""
    if payload[:4] != MAGIC:
        raise ValueError("not a hairport display payload")
    length = int(np.frombuffer(payload[4:8], dtype="<u4")[0])
    header = json.loads(payload[8:8 + length])
    base = 8 + length
    dtypes = {name: np.dtype(name).newbyteorder("<") for name in _WIRE_DTYPES.values()}
    arrays = {}
    for entry in header.pop("arrays"):
        count = int(np.prod(entry["shape"], dtype=np.int64))
        arrays[entry["name"]] = np.frombuffer(payload, dtype=dtypes[entry["dtype"]], count=count,
                                              offset=base + entry["offset"]).reshape(entry["shape"])
    return header, arrays


def colors_u8(color: np.ndarray | None) -> np.ndarray | None:
    """(N, 3) uint8 sRGB of colours in [0, 1] (None stays None)."""
    if color is None:
        return None
    return np.round(np.clip(np.nan_to_num(color, nan=0.5), 0.0, 1.0) * 255).astype(np.uint8)


def scene_arrays(points: np.ndarray, offsets: np.ndarray, inside: np.ndarray, color: np.ndarray | None,
                 body_vertices: np.ndarray, body_faces: np.ndarray, groom_rotation: np.ndarray,
                 hairline: dict, presets: dict[str, dict],
                 wrapped: tuple[np.ndarray, np.ndarray] | None = None,
                 crossing: np.ndarray | None = None) -> dict[str, np.ndarray]:
    """A job's scene, in hairport's frame.

    Parameters
    ----------
    points : (N, 3) float64
        The result's particles (meters).
    offsets : (S+1,) int64
    inside : (N,) bool
        Particles inside the target body.
    color : (N, 3) float64 in [0, 1], or None
    body_vertices : (V, 3) float64, body_faces : (F, 3) int
        The target body.
    groom_rotation : (3, 3) float64
        ``R`` with ``canonical = R @ groom axes`` (:attr:`~hairport.solver.model.frame.InputFrame.rotation`).
    hairline, presets : dict
        The target's current front hairline and each preset's edit of it (curve documents in meters:
        ``points``, ``turning_points``), as :func:`~hairport.solver.documents.hairline_document` gives them.
    wrapped : ((W, 3) float64, (G, 3) int) or None
        The source body wrapped onto a target of another topology (its vertices in the target's shape, the
        source's faces), kept as :data:`WRAPPED_ARRAYS`; None when the target was not wrapped.
    crossing : (N,) bool, optional
        Particles that start a segment passing through the target body between two particles outside it
        (kept as ``crossing`` bits; a scene without them draws none).
    """
    arrays = {
        "points": np.asarray(points, dtype=np.float32), "offsets": np.asarray(offsets, dtype=np.int64),
        "inside": np.packbits(np.asarray(inside, dtype=bool)),
        "body_vertices": np.asarray(body_vertices, dtype=np.float32),
        "body_faces": np.asarray(body_faces, dtype=np.uint32),
        "groom_rotation": np.asarray(groom_rotation, dtype=np.float64),
        "hairline_points": np.asarray(hairline["points"], dtype=np.float32).reshape(-1, 3),
        "hairline_turning": np.asarray(hairline["turning_points"], dtype=np.int32),
    }
    if color is not None:
        arrays["color"] = colors_u8(color)
    if crossing is not None:
        arrays["crossing"] = np.packbits(np.asarray(crossing, dtype=bool))
    for name, document in presets.items():
        arrays[scene_preset_array(name)] = np.asarray(document["points"], dtype=np.float32).reshape(-1, 3)
    if wrapped is not None:
        vertices, faces = wrapped
        arrays.update(zip(WRAPPED_ARRAYS, (np.asarray(vertices, dtype=np.float32),
                                           np.asarray(faces, dtype=np.uint32)), strict=True))
    return arrays


def save_scene(path: str | os.PathLike, arrays: dict[str, np.ndarray]) -> Path:
    """Write a scene as an uncompressed ``.npz`` (members are then read one by one, without pickle)."""
    with open(path, "wb") as handle:
        np.savez(handle, **arrays)
    return Path(path)


def load_scene(path: str | os.PathLike, names: tuple[str, ...] | None = None) -> dict[str, np.ndarray]:
    """The arrays ``names`` (default all) of a saved scene; only those are read."""
    try:
        with np.load(path, allow_pickle=False) as scene:
            wanted = scene.files if names is None else [name for name in names if name in scene.files]
            return {name: scene[name] for name in wanted}
    except (OSError, ValueError, zipfile.BadZipFile) as error:
        raise InputError(f"the job's scene cannot be read: {error}", code="bad_scene") from None


def strands_payload(scene: dict[str, np.ndarray], strand_ids: np.ndarray, stride: int, layer: str) -> bytes:
    """The drawn strands of a scene (or of any groom: ``points``, ``offsets``, optional ``inside`` and
    ``crossing`` bits and ``color``) in the wire format: ``positions`` (M, 3) float32, ``starts`` (K+1,) uint32,
    ``inside`` (M,) uint8 (0/1), ``crossing`` (M,) uint8 (1: the drawn segment from this vertex spans a segment
    through the body) and ``color`` (M, 3) uint8 when the groom has colours."""
    offsets = scene["offsets"]
    particles, starts = decimate(offsets, strand_ids, stride)
    arrays = {"positions": np.asarray(scene["points"], dtype=np.float32)[particles],
              "starts": starts.astype(np.uint32)}
    n_particles = int(offsets[-1])
    if "inside" in scene:
        inside = np.unpackbits(scene["inside"], count=n_particles).astype(bool)
        arrays["inside"] = inside[particles].astype(np.uint8)
    if "crossing" in scene:
        crossing = np.unpackbits(scene["crossing"], count=n_particles).astype(bool)
        arrays["crossing"] = drawn_crossing(crossing, particles, starts).astype(np.uint8)
    if "color" in scene:
        arrays["color"] = scene["color"][particles]
    header = {"layer": layer, "strands": int(len(offsets) - 1), "particles": n_particles,
              "drawn_strands": int(len(strand_ids)), "drawn_vertices": int(len(particles)), "stride": int(stride),
              "inside": int(arrays["inside"].sum()) if "inside" in arrays else None,
              "crossing": int(arrays["crossing"].sum()) if "crossing" in arrays else None}
    return encode(header, arrays)


def drawn_crossing(crossing: np.ndarray, particles: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """(M,) bool: drawn vertices whose drawn segment (to the next drawn vertex of its strand) spans a segment of
    the groom that passes through the body.

    Parameters
    ----------
    crossing : (N,) bool
        The groom's particles that start such a segment.
    particles : (M,) int64, starts : (K+1,) int64
        The drawn particles, strand by strand (:func:`decimate`).
    """
    before = np.zeros(len(crossing) + 1, dtype=np.int64)
    np.cumsum(crossing, out=before[1:])  # before[i]: crossing segments starting before particle i
    spans = np.zeros(len(particles), dtype=bool)
    if len(particles) > 1:
        spans[:-1] = before[particles[1:]] > before[particles[:-1]]
    spans[starts[1:] - 1] = False  # a strand's last drawn vertex starts no drawn segment
    return spans


def body_payload(vertices: np.ndarray, faces: np.ndarray, layer: str, **header) -> bytes:
    """A body mesh in the wire format: ``vertices`` (V, 3) float32 and ``faces`` (F, 3) uint32."""
    return encode({"layer": layer, "vertices": int(len(vertices)), "faces": int(len(faces)), **header},
                  {"vertices": np.asarray(vertices, dtype=np.float32), "faces": np.asarray(faces, dtype=np.uint32)})


def scene_preset_array(preset: str) -> str:
    """The name of the scene array holding ``preset``'s edit of the hairline."""
    return PRESET_ARRAY.format(preset)


def scene_has_wrap(scene: dict[str, np.ndarray]) -> bool:
    """Whether the scene keeps a wrapped body (its target was of another topology, or wrapped on request)."""
    return all(name in scene for name in WRAPPED_ARRAYS)


def scene_meta(scene: dict[str, np.ndarray]) -> dict:
    """The scene's ``meta`` record (the groom's units, why it has no hairline), ``{}`` when it has none."""
    return json.loads(scene["meta"].tobytes()) if "meta" in scene else {}


def hairline_json(scene: dict[str, np.ndarray]) -> dict:
    """The scene's hairlines for the page: the current one and each preset's (meters, hairport's frame), and
    the rotation to the groom's axes in which a drawn curve is sent."""
    presets = {name[len(PRESET_ARRAY.format("")):]: np.round(points.astype(np.float64), 6).tolist()
               for name, points in scene.items() if name.startswith(PRESET_ARRAY.format(""))}
    return {"units": "m", "points": np.round(scene["hairline_points"].astype(np.float64), 6).tolist(),
            "turning_points": scene["hairline_turning"].tolist(), "presets": presets,
            "groom_rotation": scene["groom_rotation"].tolist()}


def display_up(vertices: np.ndarray, up_axis: str | None) -> tuple[list[float], str]:
    """The up vector a lone character is drawn with, and how it was found: its given up axis, else the axis of
    its bounding box's longest extent (a standing body is tallest along up; a thumbnail needs no more)."""
    if up_axis:
        return AXIS_VECTORS[parse_axis(up_axis)].tolist(), "given"
    extent = np.ptp(np.asarray(vertices, dtype=np.float64), axis=0) if len(vertices) else np.ones(3)
    return np.eye(3)[int(np.argmax(extent))].tolist(), "longest extent"
