"""The head patch a hairline edit moves in: the scalp plus rings of head faces around it, as one disk."""

from __future__ import annotations

import numpy as np

from hairport.solver.body.head_frame import HeadFrame, head_frame
from hairport.solver.hairline.scalp import Scalp
from hairport.solver.mesh.topology import face_adjacency, make_disk, submesh
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError

#: rings of head faces (vertex-neighbour rings) added around the scalp; 1-3 cm each on
#: the MakeHuman head
DEFAULT_MARGIN_RINGS = 6


def head_patch(
    character: Character,
    scalp: Scalp,
    margin_rings: int = DEFAULT_MARGIN_RINGS,
    frame: HeadFrame | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A disk-shaped patch of the head around the scalp.

    The scalp's faces, grown ``margin_rings`` times by every head face (three head-dominant
    vertices, :attr:`.body.head_frame.HeadFrame.head_vertices`) sharing a vertex with the patch, then
    made a disk (holes filled, pinch vertices repaired; :func:`~hairport.solver.mesh.topology.make_disk`).

    Parameters
    ----------
    character : Character
    scalp : Scalp
        From :func:`.scalp.extract_scalp` on this character.
    margin_rings : int
        >= 0; 0 gives the scalp itself.
    frame : HeadFrame, optional
        Reuse a frame from :func:`~hairport.solver.body.head_frame.head_frame`.

    Returns
    -------
    vertices : (p,) int64
        Ascending ids of the character's vertices in the patch.
    triangles : (q, 3) int64
        The patch's faces in local numbering (into ``vertices``).
    faces : (q,) int64
        Ascending ids of the character's faces, row for row with ``triangles``.

    Raises
    ------
    InputError
        Negative ``margin_rings``, or a patch that cannot be made a disk.
    """
    if margin_rings < 0:
        raise InputError("margin_rings must be >= 0", code="bad_option")
    frame = frame or head_frame(character)
    faces = character.faces
    head_faces = frame.head_vertices[faces].all(axis=1)
    region = np.zeros(len(faces), dtype=bool)
    region[scalp.faces] = True
    for _ in range(margin_rings):
        touched = np.zeros(character.n_vertices, dtype=bool)
        touched[faces[region].ravel()] = True
        region |= head_faces & touched[faces].any(axis=1)
    weight = np.zeros(len(faces))
    weight[scalp.faces] = 1.0
    disk = make_disk(faces, region, face_adjacency(faces), weight, "head patch")
    face_ids = np.flatnonzero(disk).astype(np.int64)
    vertices, triangles = submesh(faces, face_ids)
    return vertices, triangles, face_ids
