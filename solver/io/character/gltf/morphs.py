"""A glTF mesh's morph targets (blend shapes) as the frames of a target sequence.

A frame is the mesh with its morph targets' ``POSITION`` offsets added, each scaled by the frame's weight (glTF
2.0, "Morph Targets"), placed by its node's world transform as the mesh itself is (the offsets by its linear part).
The weights of each frame come either from the file's animation (the channel whose target is the mesh's node and
whose path is ``weights``, sampled at each frame's time with its sampler's ``LINEAR``, ``STEP`` or ``CUBICSPLINE``
interpolation; frame ``f`` at ``f / frames_per_second`` seconds), or from a list given beside the file, one weight
per target and frame. Frames carry no skin: a skinned mesh's bind pose does not follow its shape.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from hairport.solver.io.character.gltf import open_gltf, read_gltf
from hairport.solver.io.character.gltf.buffers import GltfReader
from hairport.solver.io.character.mesh_file import MALFORMED, MeshFile
from hairport.solver.io.external import ALLOW_EXTERNAL_FILES
from hairport.solver.model.errors import InputError

INTERPOLATIONS = ("LINEAR", "STEP", "CUBICSPLINE")


def read_morph_frames(path: str | os.PathLike, *, times_s: np.ndarray | None = None,
                      weights: np.ndarray | None = None, max_vertices: int, max_faces: int,
                      mesh_name: str | None = None, allow_external_files: bool = ALLOW_EXTERNAL_FILES
                      ) -> list[MeshFile]:
    """The mesh at each frame (module notes).

    Parameters
    ----------
    path : path
        ``.glb`` or ``.gltf``.
    times_s : (F,) float64, optional
        Each frame's time in seconds in the file's morph animation.
    weights : (F, T) float64, optional
        Each frame's weights instead (one per morph target).
    max_vertices, max_faces, mesh_name, allow_external_files
        As :func:`~hairport.solver.io.character.gltf.read_gltf`'s.

    Returns
    -------
    frames : list of MeshFile
        In meters, without skin.

    Raises
    ------
    InputError
        ``not_animated`` for a mesh without morph targets, or without an animation of their weights when no weights
        are given; ``bad_frames`` for times outside the animation or weights of another width than the targets.
    """
    path = Path(path)
    try:
        return _frames(path, times_s, weights, max_vertices, max_faces, mesh_name, allow_external_files)
    except InputError:
        raise
    except MALFORMED as error:
        raise InputError(f"malformed glTF: {type(error).__name__}: {error}", str(path), "bad_mesh") from None


def _frames(path: Path, times_s, weights, max_vertices, max_faces, mesh_name, allow_external_files) -> list[MeshFile]:
    source = str(path)
    document, reader, (node, mesh_index, _, label) = open_gltf(path, mesh_name, allow_external_files)
    base = read_gltf(path, max_vertices=max_vertices, max_faces=max_faces, mesh_name=mesh_name,
                     allow_external_files=allow_external_files)
    offsets = _target_offsets(reader, document["meshes"][mesh_index], label, source)
    if node is not None:
        offsets = offsets @ reader.world_matrices()[node][:3, :3].T
    if weights is None:
        weights = _animated_weights(reader, document, node, len(offsets), np.asarray(times_s, dtype=np.float64),
                                    label, source)
    weights = np.asarray(weights, dtype=np.float64)
    if weights.ndim != 2 or weights.shape[1] != len(offsets):
        raise InputError(f"mesh {label!r} has {len(offsets)} morph targets; the weights given are "
                         f"{weights.shape[-1] if weights.ndim else 0} a frame", source, "bad_frames")
    return [MeshFile(base.vertices + np.tensordot(row, offsets, axes=1), base.faces, None, f"{label}#{number}",
                     base.units) for number, row in enumerate(weights)]


def _target_offsets(reader: GltfReader, mesh: dict, label: str, source: str) -> np.ndarray:
    """``(T, V, 3)``: each morph target's ``POSITION`` offsets over the mesh's primitives in order (zero where a
    target has none)."""
    primitives = mesh.get("primitives", [])
    targets = [primitive.get("targets", []) for primitive in primitives]
    counts = {len(t) for t in targets}
    if counts in (set(), {0}):
        raise InputError(f"mesh {label!r} has no morph targets, so it holds one body", source, "not_animated")
    if len(counts) > 1:
        raise InputError(f"mesh {label!r}: its primitives have different numbers of morph targets", source, "bad_mesh")
    parts = []
    for primitive, primitive_targets in zip(primitives, targets, strict=True):
        size = reader.count(primitive.get("attributes", {}).get("POSITION"), "POSITION")
        part = np.zeros((len(primitive_targets), size, 3))
        for number, target in enumerate(primitive_targets):
            if isinstance(target, dict) and "POSITION" in target:
                values = reader.accessor(target["POSITION"]).astype(np.float64).reshape(-1, 3)
                if len(values) != size:
                    raise InputError(f"mesh {label!r}: morph target {number} has {len(values)} offsets for {size} "
                                     "vertices", source, "bad_mesh")
                part[number] = values
        parts.append(part)
    offsets = np.concatenate(parts, axis=1)
    if not np.isfinite(offsets).all():
        raise InputError(f"mesh {label!r}: a morph target has a non-finite offset", source, "non_finite")
    return offsets


def _animated_weights(reader: GltfReader, document: dict, node: int | None, n_targets: int, times_s: np.ndarray,
                      label: str, source: str) -> np.ndarray:
    """``(F, T)``: the weights the file's animation gives the mesh's node at each time."""
    sampler = _weights_sampler(document, node)
    if sampler is None:
        raise InputError(f"mesh {label!r} has morph targets but no animation of their weights: give the weights of "
                         "each frame", source, "not_animated")
    interpolation = sampler.get("interpolation", "LINEAR")
    if interpolation not in INTERPOLATIONS:
        raise InputError(f"unknown interpolation {interpolation!r} of the morph animation", source, "bad_mesh")
    keys = reader.accessor(sampler["input"]).astype(np.float64).ravel()
    values = reader.accessor(sampler["output"]).astype(np.float64).ravel()
    per_key = 3 * n_targets if interpolation == "CUBICSPLINE" else n_targets
    if len(keys) == 0 or len(values) != len(keys) * per_key or not (np.diff(keys) > 0).all():
        raise InputError(f"the morph animation has {len(keys)} key times and {len(values)} weights for {n_targets} "
                         "targets", source, "bad_mesh")
    if len(times_s) and (times_s.min() < keys[0] - 1e-9 or times_s.max() > keys[-1] + 1e-9):
        raise InputError(f"frames at {times_s.min():g} to {times_s.max():g} s reach past the morph animation "
                         f"({keys[0]:g} to {keys[-1]:g} s)", source, "bad_frames")
    return sample_weights(keys, values.reshape(len(keys), -1, n_targets) if interpolation == "CUBICSPLINE"
                          else values.reshape(len(keys), n_targets), interpolation, times_s)


def _weights_sampler(document: dict, node: int | None) -> dict | None:
    """The sampler of the first animation channel that drives ``node``'s morph weights."""
    for animation in document.get("animations", []) if node is not None else []:
        samplers = animation.get("samplers", [])
        for channel in animation.get("channels", []):
            target = channel.get("target", {})
            if target.get("node") == node and target.get("path") == "weights":
                index = channel.get("sampler")
                if not isinstance(index, int) or not 0 <= index < len(samplers):
                    raise KeyError(f"animation sampler {index}")
                return samplers[index]
    return None


def sample_weights(keys: np.ndarray, values: np.ndarray, interpolation: str, times: np.ndarray) -> np.ndarray:
    """glTF's interpolation of keyed weights.

    Parameters
    ----------
    keys : (K,) float64
        Increasing key times (s).
    values : (K, T) float64, or (K, 3, T) for ``CUBICSPLINE`` (in-tangent, value, out-tangent)
    interpolation : str
        ``LINEAR``, ``STEP`` or ``CUBICSPLINE``.
    times : (F,) float64
        Within ``[keys[0], keys[-1]]``.

    Returns
    -------
    weights : (F, T) float64
    """
    times = np.clip(times, keys[0], keys[-1])
    k = np.clip(np.searchsorted(keys, times, side="right") - 1, 0, len(keys) - 1)
    after = np.minimum(k + 1, len(keys) - 1)
    span = keys[after] - keys[k]
    s = np.where(span > 0, (times - keys[k]) / np.where(span > 0, span, 1.0), 0.0)[:, None]
    if interpolation == "STEP":
        return values[k].copy()
    if interpolation == "LINEAR":
        return values[k] + s * (values[after] - values[k])
    h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
    h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
    return (h00 * values[k, 1] + h10 * span[:, None] * values[k, 2] + h01 * values[after, 1]
            + h11 * span[:, None] * values[after, 0])
