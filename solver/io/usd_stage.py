"""Opening a USD stage and reading its length unit: what the USD hair and character readers share.

``ctx`` is the reader's context: anything with ``source`` (the file's name) and ``error(problem, code)``
returning an :class:`~hairport.solver.model.errors.InputError` (a hair reader's ``ReadContext``)."""

from __future__ import annotations

import os
import re

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


def open_stage(path: str, ctx):
    """The stage of the USD file at ``path``."""
    Usd, _, _, _, Tf = pxr_modules()
    try:
        stage = Usd.Stage.Open(path, Usd.Stage.LoadAll)
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
    _, UsdGeom, _, _, _ = pxr_modules()
    meters = float(UsdGeom.GetStageMetersPerUnit(stage))
    unit = unit_of(meters)
    if unit is None:
        known = ", ".join(f"{name} ({scale:g})" for name, scale in METERS_PER_UNIT.items())
        raise ctx.error(f"the stage's metersPerUnit {meters:g} is none of hairport's units: {known}", "bad_header")
    return unit
