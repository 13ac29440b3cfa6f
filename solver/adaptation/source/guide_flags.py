"""Guides flagged in a file, and hairport's guides written as flags.

DCC tools and Unreal's groom convention mark simulation guides with a per-strand attribute
(``groom_guide``: 1 for a guide, 0 otherwise). Those strands may serve as the multi-scale
solver's guides instead of the k-means selection (:func:`flagged_guides`), and the guides a
retarget used can be written back the same way (:func:`with_guide_flags`), so that an engine
simulates the strands the solver adapted first.
"""

from __future__ import annotations

import numpy as np

from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import STRAND, Hair, HairAttribute

#: Unreal's per-strand guide flag (Epic's "Alembic for Grooms" specification)
GUIDE_FLAG = "groom_guide"
#: the dtype Unreal's convention gives the flag
GUIDE_FLAG_DTYPE = np.int16


def flagged_guides(hair: Hair, name: str = GUIDE_FLAG, max_guides: int | None = None) -> np.ndarray:
    """The strands whose attribute ``name`` is non-zero, as guides.

    Parameters
    ----------
    hair : Hair
    name : str
        A per-strand scalar attribute.
    max_guides : int, optional
        Most guides the coupled solve takes (``too_large`` above).

    Returns
    -------
    guides : (G,) int64
        Strand indices, increasing.

    Raises
    ------
    InputError
        ``no_guide_flags``: no such per-strand scalar attribute, or no strand flagged; ``too_large``.
    """
    attribute = hair.attributes.get(name)
    if attribute is None or attribute.domain != STRAND or attribute.components != 1:
        have = [key for key, value in hair.attributes.items() if value.domain == STRAND and value.components == 1]
        raise InputError(f"no per-strand attribute {name!r} flags guides; the hair has "
                         f"{', '.join(map(repr, have)) or 'no per-strand attribute'}", code="no_guide_flags")
    guides = np.flatnonzero(attribute.values).astype(np.int64)
    if len(guides) == 0:
        raise InputError(f"attribute {name!r} flags no strand as a guide", code="no_guide_flags")
    if max_guides is not None and len(guides) > max_guides:
        raise InputError(f"attribute {name!r} flags {len(guides):,} guides, more than the {max_guides:,} the coupled "
                         "solve takes", code="too_large")
    return guides


def with_guide_flags(hair: Hair, guides: np.ndarray, name: str = GUIDE_FLAG) -> Hair:
    """The hairstyle with attribute ``name`` (int16, per strand) 1 on ``guides (G,) int64`` and 0 elsewhere
    (replacing one it had)."""
    flags = np.zeros(hair.n_strands, dtype=GUIDE_FLAG_DTYPE)
    flags[guides] = 1
    attributes = {**hair.attributes, name: HairAttribute(flags, STRAND)}
    return Hair(hair.points, hair.offsets, hair.thickness, hair.color, attributes)
