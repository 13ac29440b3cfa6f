"""MakeHuman's macro parameters and the weights they give the macro target files.

The macro mixing follows MakeHuman 1.1 (``apps/human.py``, ``humanmodifier.py``) and MPFB2
(``targetservice.py``): each macro variable is turned into weights of its anchor values by
piecewise-linear interpolation, and each macro target file (one per combination of anchors)
gets the product of the weights of the anchors in its name. See :func:`macro_target_weights`.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from hairport.solver.model.errors import InputError
from hairport.solver.synthetic.assets import SHAPE_TARGET_GROUPS

#: the ethnic mix, as MakeHuman names it
RACES: tuple[str, ...] = ("african", "asian", "caucasian")
#: the race weights must sum to 1 up to this (unitless)
RACE_SUM_TOLERANCE = 1e-6

#: MakeHuman's age axis: parameter value -> years (piecewise linear between these anchors),
#: and the names of the anchors in the macro target files
AGE_PARAM_ANCHORS = (0.0, 0.1875, 0.5, 1.0)
AGE_YEARS_ANCHORS = (1.0, 11.0, 25.0, 90.0)
AGE_ANCHOR_NAMES = ("baby", "child", "young", "old")


def age_from_years(years: float) -> float:
    """MakeHuman's age parameter for an age in years (1 y -> 0, 11 y -> 0.1875, 25 y -> 0.5, 90 y -> 1)."""
    if not (AGE_YEARS_ANCHORS[0] <= years <= AGE_YEARS_ANCHORS[-1]):
        raise InputError(f"age {years} years is outside MakeHuman's range 1..90", "age", "bad_parameter")
    return float(np.interp(years, AGE_YEARS_ANCHORS, AGE_PARAM_ANCHORS))


def years_from_age(age: float) -> float:
    """Inverse of :func:`age_from_years`."""
    return float(np.interp(age, AGE_PARAM_ANCHORS, AGE_YEARS_ANCHORS))


@dataclass(frozen=True)
class MakeHumanParams:
    """MakeHuman's macro parameters plus optional local shape targets.

    All macro values are in ``[0, 1]``; 0.5 is MakeHuman's default for each.

    Attributes
    ----------
    gender : float
        0 female, 1 male.
    age : float
        0 = 1 year, 0.1875 = 11 years, 0.5 = 25 years, 1 = 90 years (see :func:`age_from_years`).
    muscle, weight : float
        0 minimal, 0.5 average, 1 maximal.
    height : float
        0 short, 1 tall (0.5 applies no height target).
    proportions : float
        0 uncommon, 1 ideal proportions (0.5 applies no proportions target).
    african, asian, caucasian : float
        Ethnic mix, non-negative, summing to 1.
    targets : tuple of (str, float)
        Extra shape targets and weights in ``[0, 1]``, named by their path under ``targets/``
        without extension, e.g. ``("head/head-round", 0.5)``; a mapping is accepted and stored
        sorted. Allowed folders: :data:`SHAPE_TARGET_GROUPS`. Names are checked against the
        asset files when building.
    """

    gender: float = 0.5
    age: float = 0.5
    muscle: float = 0.5
    weight: float = 0.5
    height: float = 0.5
    proportions: float = 0.5
    african: float = 1.0 / 3.0
    asian: float = 1.0 / 3.0
    caucasian: float = 1.0 / 3.0
    targets: tuple[tuple[str, float], ...] | Mapping[str, float] = field(default=())

    def __post_init__(self) -> None:
        for name in ("gender", "age", "muscle", "weight", "height", "proportions", *RACES):
            value = getattr(self, name)
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise InputError(f"{name} must be a number, got {value!r}", name, "bad_parameter") from None
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                raise InputError(f"{name} must lie in [0, 1], got {value}", name, "bad_parameter")
            object.__setattr__(self, name, value)
        race_sum = self.african + self.asian + self.caucasian
        if abs(race_sum - 1.0) > RACE_SUM_TOLERANCE:
            raise InputError(
                f"african + asian + caucasian must sum to 1, got {race_sum:.6g}", "race", "bad_parameter"
            )
        raw = self.targets
        items = raw.items() if isinstance(raw, Mapping) else raw
        pairs: dict[str, float] = {}
        try:
            for key, value in items:
                pairs[str(key)] = float(value)
        except (TypeError, ValueError):
            raise InputError("targets must map target names to numbers", "targets", "bad_parameter") from None
        for key, value in pairs.items():
            group = key.rsplit("/", 1)[0] if "/" in key else ""
            if group not in SHAPE_TARGET_GROUPS:
                raise InputError(
                    f"target {key!r} is not in one of the folders {', '.join(SHAPE_TARGET_GROUPS)} "
                    f"(macro targets are set by the macro parameters)",
                    "targets",
                    "unknown_target",
                )
            if not (math.isfinite(value) and 0.0 <= value <= 1.0):
                raise InputError(
                    f"weight of target {key!r} must lie in [0, 1], got {value}", "targets", "bad_parameter"
                )
        object.__setattr__(self, "targets", tuple(sorted(pairs.items())))

    @property
    def target_weights(self) -> dict[str, float]:
        """The extra targets as a dict."""
        return dict(self.targets)


def blend_params(first: MakeHumanParams, last: MakeHumanParams, t: float) -> MakeHumanParams:
    """The parameters ``t`` of the way from ``first`` to ``last`` (``t`` in [0, 1]): every macro and every extra
    target's weight (0 where one side lacks it; a weight of 0 left out) moved linearly, as a character customiser's
    sliders move."""
    macros = {name: (1.0 - t) * getattr(first, name) + t * getattr(last, name)
              for name in ("gender", "age", "muscle", "weight", "height", "proportions", *RACES)}
    ours, theirs = first.target_weights, last.target_weights
    targets = {name: (1.0 - t) * ours.get(name, 0.0) + t * theirs.get(name, 0.0) for name in sorted({*ours, *theirs})}
    return MakeHumanParams(**macros, targets={name: weight for name, weight in targets.items() if weight > 0.0})


def _two_sided(value: float, low: str, mid: str | None, high: str) -> dict[str, float]:
    """Weights of a variable with anchors 0 (low), 0.5 (mid), 1 (high)."""
    low_w = max(0.0, 1.0 - 2.0 * value)
    high_w = max(0.0, 2.0 * value - 1.0)
    weights = {low: low_w, high: high_w}
    if mid is not None:
        weights[mid] = 1.0 - low_w - high_w
    return weights


def _age_weights(age: float) -> dict[str, float]:
    """Anchors baby (1 y), child (11 y), young (25 y), old (90 y) at 0, 0.1875, 0.5, 1."""
    weights = dict.fromkeys(AGE_ANCHOR_NAMES, 0.0)
    anchors = AGE_PARAM_ANCHORS
    names = AGE_ANCHOR_NAMES
    k = int(np.clip(np.searchsorted(anchors, age, side="right") - 1, 0, len(anchors) - 2))
    t = (age - anchors[k]) / (anchors[k + 1] - anchors[k])
    weights[names[k]] = 1.0 - t
    weights[names[k + 1]] = t
    return weights


def macro_variable_weights(params: MakeHumanParams) -> dict[str, dict[str, float]]:
    """Weight of each anchor value of each macro variable.

    Returns
    -------
    weights : dict
        ``{"gender": {"female": w, "male": w}, "age": {...4}, "muscle": {...3}, "weight":
        {...3}, "height": {"minheight", "maxheight"}, "proportions": {"uncommonproportions",
        "idealproportions"}, "race": {...3}}``. Height and proportions have no target for
        their middle value, so their two weights sum to ``|2v - 1|``.
    """
    height = _two_sided(params.height, "minheight", None, "maxheight")
    proportions = _two_sided(params.proportions, "uncommonproportions", None, "idealproportions")
    return {
        "gender": {"female": 1.0 - params.gender, "male": params.gender},
        "age": _age_weights(params.age),
        "muscle": _two_sided(params.muscle, "minmuscle", "averagemuscle", "maxmuscle"),
        "weight": _two_sided(params.weight, "minweight", "averageweight", "maxweight"),
        "height": height,
        "proportions": proportions,
        "race": {race: getattr(params, race) for race in RACES},
    }


def macro_target_weights(params: MakeHumanParams) -> dict[str, float]:
    """The macro targets to apply and their weights (MakeHuman 1.1 / MPFB2 scheme).

    Every combination of anchors gets the product of the anchor weights:

    * ``macrodetails/{race}-{gender}-{age}``: race x gender x age;
    * ``macrodetails/universal-{gender}-{age}-{muscle}-{weight}``: gender x age x muscle x weight;
    * ``macrodetails/height/{gender}-{age}-{muscle}-{weight}-{min|max}height``: ... x height;
    * ``macrodetails/proportions/{gender}-{age}-{muscle}-{weight}-{uncommon|ideal}proportions``:
      ... x proportions (there are no baby proportions targets; MPFB skips them too).

    Unlike MPFB no cutoff is applied (MPFB drops weights <= 0.01); zero weights are omitted.

    Returns
    -------
    weights : dict of str to float
        Target name (path under ``targets/`` without extension) -> weight > 0.
    """
    w = macro_variable_weights(params)
    out: dict[str, float] = {}

    def nonzero(variable: str) -> list[tuple[str, float]]:
        return [(k, v) for k, v in w[variable].items() if v > 0.0]

    gender, age, muscle, weight = nonzero("gender"), nonzero("age"), nonzero("muscle"), nonzero("weight")
    for (r, wr), (g, wg), (a, wa) in itertools.product(nonzero("race"), gender, age):
        out[f"macrodetails/{r}-{g}-{a}"] = wr * wg * wa
    for (g, wg), (a, wa), (m, wm), (x, wx) in itertools.product(gender, age, muscle, weight):
        base = wg * wa * wm * wx
        stem = f"{g}-{a}-{m}-{x}"
        out[f"macrodetails/universal-{stem}"] = base
        for h, wh in nonzero("height"):
            out[f"macrodetails/height/{stem}-{h}"] = base * wh
        if a != "baby":
            for p, wp in nonzero("proportions"):
                out[f"macrodetails/proportions/{stem}-{p}"] = base * wp
    return {k: v for k, v in out.items() if v > 0.0}
