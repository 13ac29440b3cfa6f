"""Opening a USD stage and reading its length unit: what the USD hair and character readers share.

``ctx`` is the reader's context: anything with ``source`` (the file's name) and ``error(problem, code)``
returning an :class:`~hairport.solver.model.errors.InputError` (a hair reader's ``ReadContext``).

Opening (:func:`open_stage`): unless external files are allowed (the command line's own files), the
file's root layer is opened alone and every file it names refuses it (code ``external_reference``,
:mod:`~hairport.solver.io.external`) before anything is composed; the stage is then composed from
that one in-memory layer, and a stage that still used another layer is refused too (a name the walk
of :mod:`~hairport.solver.io.usd.assets` did not know). The stage's length unit is the root layer's
``metersPerUnit``: USD takes stage metadata from the root layer only, so :func:`root_layer_units`
reads it without composing anything.
"""

from __future__ import annotations

import os
import re

from hairport.solver.io.external import ALLOW_EXTERNAL_FILES, external_reference
from hairport.solver.io.usd.assets import asset_names
from hairport.solver.model.units import METERS_PER_UNIT

#: a stage's metersPerUnit names a hairport unit when it is within this relative distance of it
UNIT_TOLERANCE = 1e-6


def pxr_modules():
    """``(Usd, UsdGeom, Vt, Sdf, Tf)``; usd-core is a dependency, imported only where USD is read or written."""
    from pxr import Sdf, Tf, Usd, UsdGeom, Vt

    return Usd, UsdGeom, Vt, Sdf, Tf


def unit_of(meters_per_unit: float) -> str | None:
    """The name in :data:`METERS_PER_UNIT` of a stage's ``metersPerUnit``, or None."""
    for name, scale in METERS_PER_UNIT.items():
        if abs(meters_per_unit - scale) <= UNIT_TOLERANCE * scale:
            return name
    return None


def open_stage(path: str, ctx, allow_external_files: bool = ALLOW_EXTERNAL_FILES):
    """The stage of the USD file at ``path`` (module notes).

    Parameters
    ----------
    path : str
    ctx : reader context
    allow_external_files : bool
        Compose what the file names (sublayers, references, payloads, clips) from the disk; else
        a file naming any other file is refused.

    Raises
    ------
    InputError
        ``bad_header`` for bytes USD cannot open; ``external_reference``.
    """
    Usd, _, _, _, _ = pxr_modules()
    if allow_external_files:
        return _composed(lambda: Usd.Stage.Open(path, Usd.Stage.LoadAll), ctx)
    layer = open_root_layer(path, ctx)
    refuse_external_names(layer, ctx)
    stage = _composed(lambda: Usd.Stage.Open(layer, Usd.Stage.LoadAll), ctx)
    others = [used for used in stage.GetUsedLayers() if used not in (layer, stage.GetSessionLayer())]
    if others:
        raise external_reference("layer", others[0].identifier, ctx.source, more=len(others) - 1)
    return stage


def open_root_layer(path: str, ctx):
    """The file's layer alone (``Sdf.Layer``), nothing it names opened."""
    _, _, _, Sdf, Tf = pxr_modules()
    try:
        layer = Sdf.Layer.OpenAsAnonymous(path)
    except Tf.ErrorException as error:
        raise ctx.error(f"not a readable USD stage: {usd_reason(error, ctx)}", "bad_header") from None
    if layer is None:
        raise ctx.error("not a readable USD stage", "bad_header")
    return layer


def refuse_external_names(layer, ctx) -> None:
    """Refuse a layer that names any file (``external_reference``, the first named, and how many more)."""
    _, _, _, _, Tf = pxr_modules()
    try:
        names = list(asset_names(layer))
    except Tf.ErrorException as error:  # a damaged value met on walking it
        raise ctx.error(f"damaged USD data: {usd_reason(error, ctx)}", "bad_header") from None
    if names:
        kind, where, name = names[0]
        raise external_reference(kind, name, ctx.source, where if where != "/" else "", len(names) - 1)


def _composed(open_call, ctx):
    _, _, _, _, Tf = pxr_modules()
    try:
        stage = open_call()
    except Tf.ErrorException as error:
        raise ctx.error(f"not a readable USD stage: {usd_reason(error, ctx)}", "bad_header") from None
    if stage is None:
        raise ctx.error("not a readable USD stage", "bad_header")
    return stage


def usd_reason(error: Exception, ctx) -> str:
    """USD's own reason (quoted after its source locations), our temporary file's name replaced by the source's."""
    try:
        text = str(error)
    except UnicodeError:  # USD quotes the damaged bytes themselves
        text = ""
    reasons = re.findall(r" : '(.*?)'(?= Error in |$)", " ".join(text.split()))
    reason = reasons[0] if reasons else "unknown"
    reason = re.sub(r"/\S*hairport-read-\S*?/groom\.\w+", os.path.basename(ctx.source), reason)
    return reason[:200]


def stage_units(stage, ctx) -> str:
    """The hairport unit of a stage's ``metersPerUnit`` (``bad_header`` when it is none)."""
    _, UsdGeom, _, _, _ = pxr_modules()
    return _named_unit(float(UsdGeom.GetStageMetersPerUnit(stage)), ctx)


def root_layer_units(layer, ctx) -> str:
    """:func:`stage_units` of the stage of ``layer``, read from the layer alone (module notes): its
    ``metersPerUnit``, else USD's fallback."""
    root = layer.pseudoRoot
    field = "metersPerUnit"
    meters = root.GetInfo(field) if root.HasInfo(field) else root.GetFallbackForInfo(field)
    try:
        return _named_unit(float(meters), ctx)
    except (TypeError, ValueError):
        raise ctx.error(f"the stage's metersPerUnit is not a number: {type(meters).__name__}", "bad_header") from None


def _named_unit(meters: float, ctx) -> str:
    unit = unit_of(meters)
    if unit is None:
        known = ", ".join(f"{name} ({scale:g})" for name, scale in METERS_PER_UNIT.items())
        raise ctx.error(f"the stage's metersPerUnit {meters:g} is none of hairport's units: {known}", "bad_header")
    return unit
