"""A hairline edit as the user asks for it: a preset with an amount, or a drawn curve, and how the roots follow."""

from __future__ import annotations

from dataclasses import dataclass

from hairport.solver.hairline.curve import HairlineCurve, parse_hairline_curve, read_hairline_curve
from hairport.solver.hairline.presets import check_amount, check_preset, parse_preset
from hairport.solver.hairline.scalp import DEFAULT_MIN_TRIANGLES
from hairport.solver.mesh.parameterization import check_parameterization
from hairport.solver.model.errors import InputError

#: smallest refined scalp accepted (triangles)
MIN_REFINED_TRIANGLES = 16
#: how the scalp's interior follows the hairline: Eq. 15 (ours), or Section 7.5's alternatives
RELOCATION_METHODS = ("membrane", "harmonic", "rbf2d", "rbf3d")


def unknown_method(method: str) -> InputError:
    """The refusal of a relocation method not in :data:`RELOCATION_METHODS` (code ``bad_option``)."""
    return InputError(f"unknown relocation method {method!r}; expected one of {', '.join(RELOCATION_METHODS)}",
                      code="bad_option")


@dataclass(frozen=True)
class HairlineEdit:
    """A requested hairline edit.

    Attributes
    ----------
    preset : str or None
        One of :data:`.presets.PRESETS` (exclusive with ``curve``).
    amount : float
        In [0, 1], for a preset.
    curve : HairlineCurve or None
        A drawn front hairline.
    method : str
        One of :data:`RELOCATION_METHODS`.
    parameterization : str
        One of :data:`~hairport.solver.mesh.parameterization.PARAMETERIZATIONS`.
    min_triangles : int
        Resolution of the refined scalp.
    """

    preset: str | None = None
    amount: float = 1.0
    curve: HairlineCurve | None = None
    method: str = "membrane"
    parameterization: str = "harmonic"
    min_triangles: int = DEFAULT_MIN_TRIANGLES

    def validate(self) -> None:
        if (self.preset is None) == (self.curve is None):
            raise InputError("a hairline edit needs exactly one of a preset or a curve", code="bad_option")
        if self.preset is not None:
            check_preset(self.preset)
            check_amount(self.amount)
        if self.method not in RELOCATION_METHODS:
            raise unknown_method(self.method)
        check_parameterization(self.parameterization)
        if self.min_triangles < MIN_REFINED_TRIANGLES:
            raise InputError(f"option min_triangles must be >= {MIN_REFINED_TRIANGLES}", code="bad_option")

    def describe(self) -> str:
        return f"{self.preset}:{self.amount:g}" if self.preset is not None else "curve"


def hairline_edit_from_request(document: dict) -> HairlineEdit:
    """A validated hairline edit from the API's ``hairline`` object: ``preset`` with
    ``amount``, or ``curve`` (a curve document), plus ``method`` and ``parameterization``."""
    preset, curve = document.get("preset"), document.get("curve")
    return hairline_edit(
        preset=None if preset is None else f"{preset}:{document.get('amount', 1.0)}", curve=curve,
        method=document.get("method", "membrane"), parameterization=document.get("parameterization", "harmonic"),
    )


def hairline_edit(
    preset: str | None = None,
    curve_path=None,
    curve: dict | None = None,
    method: str = "membrane",
    parameterization: str = "harmonic",
) -> HairlineEdit:
    """A validated hairline edit from a preset ``NAME[:AMOUNT]``, a curve JSON file or a
    parsed curve document (exactly one)."""
    given = sum(x is not None for x in (preset, curve_path, curve))
    if given != 1:
        raise InputError("give exactly one of a hairline preset, a curve file or a curve", code="bad_option")
    if preset is not None:
        name, amount = parse_preset(preset)
        edit = HairlineEdit(preset=name, amount=amount, method=method, parameterization=parameterization)
    else:
        parsed = read_hairline_curve(curve_path) if curve_path is not None else parse_hairline_curve(curve)
        edit = HairlineEdit(curve=parsed, method=method, parameterization=parameterization)
    edit.validate()
    return edit
