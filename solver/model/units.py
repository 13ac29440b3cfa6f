"""Length units. hairport works in meters internally; inputs are converted on load."""

from __future__ import annotations

from hairport.solver.model.errors import InputError

METERS_PER_UNIT: dict[str, float] = {"m": 1.0, "dm": 0.1, "cm": 0.01, "mm": 0.001}
#: the length units files may be in
UNITS: tuple[str, ...] = tuple(METERS_PER_UNIT)


def unit_scale(units: str) -> float:
    """Factor that converts a length in ``units`` to meters.

    Parameters
    ----------
    units : str
        One of ``m``, ``dm``, ``cm``, ``mm``.

    Returns
    -------
    scale : float
    """
    try:
        return METERS_PER_UNIT[units]
    except KeyError:
        raise InputError(
            f"unknown length unit {units!r}; expected one of {', '.join(METERS_PER_UNIT)}",
            code="unknown_units",
        ) from None
