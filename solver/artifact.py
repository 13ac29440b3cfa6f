"""The adaptable-hairstyle artifact (``.hpa``): everything ``preprocess`` computed, on disk.

One uncompressed ``.npz`` (a zip of ``.npy`` arrays, read without pickle) holding the
source character (mesh, skeleton, skin weights), the hairstyle, the anchors (Eq. 2-3), the
guides and both kNN sets (Eq. 8-9, Eq. 14), and a ``meta`` JSON record: the format name
and version, the hairport version that wrote it, the preprocessing options, and a SHA-256
digest of every array's dtype, shape and bytes. Loading checks the format, the version
and the digest before anything is used, so an artifact of another format version, a
truncated or an altered one is refused with an :class:`~hairport.solver.model.errors.InputError`.

Everything else retargeting needs (Eq. 5/7/10 operators, the fine level's source arrays)
is rebuilt from these arrays deterministically, so a retarget from a loaded artifact equals
one from memory bit for bit.
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from hairport import __version__
from hairport.solver.adaptable import AdaptableHairstyle
from hairport.solver.adaptation.multiscale import MultiscaleModel
from hairport.solver.adaptation.source.neighbours import Neighbours
from hairport.solver.display import colors_u8
from hairport.solver.model.character import Character, Skeleton
from hairport.solver.model.errors import InputError
from hairport.solver.model.files import atomic_write
from hairport.solver.model.frame import InputFrame
from hairport.solver.model.hair import Hair, HairAttribute
from hairport.solver.model.json_input import parse_json
from hairport.solver.options import PreprocessOptions
from hairport.solver.transfer.anchors import ANCHOR_BY_BONES, Anchors

FORMAT_NAME = "hairport-adaptable-hairstyle"
#: bump when the arrays or their meaning change. Version 2: compact indices (int16 anchor bones,
#: int32 anchor faces and neighbour indices) and the frame offsets of the fallback particles only.
#: Version 3: the hairstyle's attributes (meta ``hair_attributes``, arrays ``hair_attribute_<i>``)
FORMAT_VERSION = 3
#: versions this hairport reads: version 1 (int64 indices, a frame offset row per particle) is
#: converted on load; versions 1 and 2 have no attributes; others are refused
READABLE_VERSIONS = (1, 2, 3)
HAIR_ATTRIBUTE = "hair_attribute_{}"
EXTENSION = ".hpa"


def _arrays(adaptable) -> dict[str, np.ndarray]:
    source, hair, anchors, ms = adaptable.source, adaptable.hair, adaptable.anchors, adaptable.multiscale
    skeleton = source.skeleton
    weights = sp.csr_matrix(source.weights if source.weights is not None else (len(source.vertices), 0))
    arrays = {
        "source_vertices": source.vertices,
        "source_faces": source.faces,
        # a source anchored by its surface may have no skeleton: empty arrays, no bone names
        "skeleton_parents": skeleton.parents if skeleton is not None else np.zeros(0, np.int64),
        "skeleton_heads": skeleton.heads if skeleton is not None else np.zeros((0, 3)),
        "skeleton_tails": skeleton.tails if skeleton is not None else np.zeros((0, 3)),
        "weights_data": weights.data,
        "weights_indices": weights.indices.astype(np.int64),
        "weights_indptr": weights.indptr.astype(np.int64),
        "hair_points": hair.points,
        "hair_offsets": hair.offsets,
        "anchor_bone": anchors.bone,
        "anchor_face": anchors.face,
        "anchor_barycentric": anchors.barycentric,
        "anchor_eta": anchors.eta,
        "anchor_frame_offset": anchors.frame_offset,
        "anchor_fallback": anchors.fallback,
        "guides": ms.guides,
        "guide_neighbour_index": ms.guide_neighbours.index,
        "guide_neighbour_weight": ms.guide_neighbours.weight,
        "fine_neighbour_index": ms.fine_neighbours.index,
        "fine_neighbour_weight": ms.fine_neighbours.weight,
    }
    if hair.thickness is not None:
        arrays["hair_thickness"] = hair.thickness
    if hair.color is not None:
        arrays["hair_color"] = hair.color
    for index, attribute in enumerate(hair.attributes.values()):
        arrays[HAIR_ATTRIBUTE.format(index)] = attribute.values
    return {name: np.ascontiguousarray(value) for name, value in arrays.items()}


def _digest(arrays: dict[str, np.ndarray]) -> str:
    digest = hashlib.sha256()
    for name in sorted(arrays):
        value = arrays[name]
        digest.update(f"{name}|{value.dtype.str}|{value.shape}|".encode())
        if value.size:  # memoryview cannot cast an empty array (e.g. no fine level: every strand a guide)
            digest.update(memoryview(value).cast("B"))
    return digest.hexdigest()


def save_adaptable(adaptable, path: str | os.PathLike) -> Path:
    """Write ``adaptable`` (an :class:`~hairport.solver.adaptable.AdaptableHairstyle`) to ``path`` atomically.

    Returns
    -------
    path : Path
    """
    path = Path(path)
    arrays = _arrays(adaptable)
    meta = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "hairport_version": __version__,
        "options": {
            "k": adaptable.options.k,
            "sigma": adaptable.options.sigma,
            "guides": adaptable.options.guides,
            "guide_seed": adaptable.options.guide_seed,
            "guides_from": adaptable.options.guides_from,
            "anchoring": adaptable.options.anchoring,
        },
        "bone_names": list(adaptable.bone_names),
        "source_name": adaptable.source.name,
        "timings": adaptable.timings,
        "input_frame": adaptable.frame.to_dict(),
        "input_report": adaptable.input_report,
        "hair_attributes": [[name, attribute.domain, attribute.role] for name, attribute in adaptable.hair.attributes.items()],
        "digest": _digest(arrays),
    }
    arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    return atomic_write(path, lambda handle: np.savez(handle, **arrays))


def load_adaptable(path: str | os.PathLike):
    """Read an artifact written by :func:`save_adaptable`.

    Raises
    ------
    InputError
        ``code="bad_artifact"`` for a file that is not a readable artifact (truncated,
        altered, another format), ``code="artifact_version"`` for another format version.
    FileNotFoundError
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such artifact")
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays = {name: archive[name] for name in archive.files}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError, KeyError) as error:
        raise InputError(f"not a readable adaptable hairstyle ({error})", str(path), "bad_artifact") from None
    try:
        meta = parse_json(arrays.pop("meta").tobytes(), str(path), "bad_artifact", "the meta record")
    except KeyError:
        raise InputError("not an adaptable hairstyle: no readable meta record", str(path), "bad_artifact") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        raise InputError("not an adaptable hairstyle (unknown format)", str(path), "bad_artifact")
    if meta.get("format_version") not in READABLE_VERSIONS:
        raise InputError(
            f"adaptable hairstyle of format version {meta.get('format_version')}, this hairport reads versions "
            f"{', '.join(map(str, READABLE_VERSIONS))}; run `hairport preprocess` again",
            str(path),
            "artifact_version",
        )
    if _digest(arrays) != meta.get("digest"):
        raise InputError("adaptable hairstyle is corrupted (digest mismatch)", str(path), "bad_artifact")
    try:
        bone_names = tuple(meta["bone_names"])
        skeleton = weights = None
        if bone_names:
            skeleton = Skeleton(bone_names, arrays["skeleton_parents"], arrays["skeleton_heads"], arrays["skeleton_tails"])
            weights = sp.csr_matrix(
                (arrays["weights_data"], arrays["weights_indices"], arrays["weights_indptr"]),
                shape=(len(arrays["source_vertices"]), skeleton.n_bones),
            )
        source = Character(
            arrays["source_vertices"], arrays["source_faces"], skeleton, weights, meta.get("source_name", "source")
        )
        attributes = {name: HairAttribute(arrays[HAIR_ATTRIBUTE.format(index)], domain, role)
                      for index, (name, domain, role) in enumerate(meta.get("hair_attributes", []))}
        hair = Hair(
            arrays["hair_points"], arrays["hair_offsets"], arrays.get("hair_thickness"), arrays.get("hair_color"),
            attributes,
        )
        frame_offset = arrays["anchor_frame_offset"]
        if meta["format_version"] == 1:  # a row per particle, zeros but for the fallback particles
            if len(frame_offset) != len(arrays["anchor_fallback"]):
                raise InputError("adaptable hairstyle arrays disagree in particle count", str(path), "bad_artifact")
            frame_offset = frame_offset[arrays["anchor_fallback"].astype(bool)]
        anchors = Anchors(
            arrays["anchor_bone"], arrays["anchor_face"], arrays["anchor_barycentric"], arrays["anchor_eta"],
            frame_offset, arrays["anchor_fallback"],
        )
        multiscale = MultiscaleModel(
            arrays["guides"],
            Neighbours(arrays["guide_neighbour_index"], arrays["guide_neighbour_weight"]),
            Neighbours(arrays["fine_neighbour_index"], arrays["fine_neighbour_weight"]),
        )
        # version-1 artifacts written before surface anchoring were all anchored by bones
        options = PreprocessOptions(**{"anchoring": ANCHOR_BY_BONES, **meta["options"]})
        frame = InputFrame.from_dict(meta.get("input_frame"))
    except KeyError as error:
        raise InputError(f"adaptable hairstyle lacks {error}", str(path), "bad_artifact") from None
    except (ValueError, TypeError) as error:  # arrays of inconsistent shapes, a malformed attribute list
        raise InputError(f"adaptable hairstyle arrays disagree ({error})", str(path), "bad_artifact") from None
    n = hair.n_particles
    if any(len(a) != n for a in (anchors.bone, anchors.face, anchors.barycentric, anchors.eta, anchors.fallback)):
        raise InputError("adaptable hairstyle arrays disagree in particle count", str(path), "bad_artifact")
    return AdaptableHairstyle(source, hair, anchors, multiscale, options, bone_names, dict(meta.get("timings", {})),
                              frame, dict(meta.get("input_report") or {}))


#: what :func:`source_scene` reads of an artifact: the source groom and body (hairport's frame)
SOURCE_SCENE_MEMBERS = {"hair_points": "points", "hair_offsets": "offsets", "hair_color": "color",
                        "source_vertices": "body_vertices", "source_faces": "body_faces"}


def source_scene(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """The source groom and body of an artifact for display (:mod:`~hairport.solver.display`): ``points`` (N, 3)
    float32, ``offsets``, ``color`` (N, 3) uint8 when the groom has colours, ``body_vertices`` float32 and
    ``body_faces`` uint32. Only those members are read (the artifact's digest, which covers them all, is checked
    when a retarget loads it)."""
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays = {name: archive[member] for member, name in SOURCE_SCENE_MEMBERS.items() if member in archive.files}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as error:
        raise InputError(f"not a readable adaptable hairstyle ({error})", str(path), "bad_artifact") from None
    missing = {"points", "offsets", "body_vertices", "body_faces"} - set(arrays)
    if missing:
        raise InputError(f"not an adaptable hairstyle: no {', '.join(sorted(missing))}", str(path), "bad_artifact")
    arrays["points"] = arrays["points"].astype(np.float32)
    arrays["body_vertices"] = arrays["body_vertices"].astype(np.float32)
    arrays["body_faces"] = arrays["body_faces"].astype(np.uint32)
    if "color" in arrays:
        arrays["color"] = colors_u8(arrays["color"])
    return arrays
