"""The head patch a hairline edit moves in: the scalp plus rings of head faces around it, as one disk.

The margin is about 10 cm (:data:`MARGIN_CROWN_SHARE` of the crown height) whatever the
mesh's density: its rings follow from the scalp's edge lengths.

On real character meshes the patch stays on the skin shell that carries the scalp (eyes,
teeth and lashes are other shells; :mod:`~hairport.solver.mesh.shells`) and keeps clear of
gaps in the mesh: a face joins only when each corner is at most
:data:`GAP_CLEARANCE_FACTOR` times as far from the scalp as from the mesh's border (distances
along the skin's edges), so the margin stops between the brows and an open eye socket
instead of reaching around it (a ring around a gap is no disk). Where it still would, the
margin loses rings until the patch is a disk.
"""

from __future__ import annotations

import numpy as np

from hairport.solver.body.head_frame import HeadFrame, head_frame
from hairport.solver.hairline.scalp import Scalp, check_region_disk
from hairport.solver.mesh.shells import border_vertices, edge_distance, shell_of
from hairport.solver.mesh.topology import face_adjacency, half_edges, is_disk, repair_disk, submesh
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError

#: the margin around the scalp, as a share of the crown height: about 10 cm, i.e. six rings of
#: head faces on every MakeHuman preset (crown / mean scalp edge 8.3-9.3), twelve on a mesh
#: twice as fine; the rings follow from the mesh's density (:func:`default_margin_rings`)
MARGIN_CROWN_SHARE = 0.68
#: a face joins the margin when each corner is at most this many times as far from the scalp
#: as from the mesh's border (1: the half-way line between them)
GAP_CLEARANCE_FACTOR = 2.0
#: a hairline edit that leaves the head patch is blamed on a gap in the mesh this close (m)
#: to the current front hairline
GAP_HINT_M = 0.03


def clear_of_gaps(character: Character, scalp: Scalp, shell: np.ndarray) -> np.ndarray:
    """(F,) bool: faces of ``shell (F,) bool`` whose corners are at most
    :data:`GAP_CLEARANCE_FACTOR` times as far from the scalp as from the shell's border
    (every face of a shell without a border)."""
    faces = character.faces
    skin = faces[shell]
    border = border_vertices(skin, character.n_vertices)
    if not border.any():
        return shell.copy()
    at_scalp = np.zeros(character.n_vertices, dtype=bool)
    at_scalp[scalp.vertices] = True
    to_scalp = edge_distance(character.vertices, skin, at_scalp)
    to_border = edge_distance(character.vertices, skin, border)
    clear = to_scalp <= GAP_CLEARANCE_FACTOR * to_border
    return shell & clear[faces].all(axis=1)


def default_margin_rings(character: Character, scalp: Scalp, frame: HeadFrame) -> int:
    """Rings of head faces that make a margin of :data:`MARGIN_CROWN_SHARE` of the crown height
    around the scalp: that length over the scalp's mean edge length, rounded (at least 1)."""
    points = character.vertices[scalp.vertices]
    edges = half_edges(scalp.triangles)
    mean_edge = float(np.linalg.norm(points[edges[:, 0]] - points[edges[:, 1]], axis=1).mean())
    return max(1, int(round(MARGIN_CROWN_SHARE * frame.crown / mean_edge)))


def gap_hint(character: Character, patch_faces: np.ndarray, hairline: np.ndarray) -> str:
    """Words for an edit that leaves the head patch when a gap in the mesh limits the patch:
    the border of the patch's shell within :data:`GAP_HINT_M` of ``hairline (f, 3)``, or ""."""
    seed = np.zeros(character.n_faces, dtype=bool)
    seed[patch_faces] = True
    border = np.flatnonzero(border_vertices(character.faces[shell_of(character.faces, seed)], character.n_vertices))
    if len(border) == 0:
        return ""
    distance = np.linalg.norm(character.vertices[border][:, None] - hairline[None], axis=2).min(axis=1)
    near = border[distance <= GAP_HINT_M]
    if len(near) == 0:
        return ""
    return (f"; a gap in the mesh {100 * distance.min():.1f} cm from the hairline, near "
            f"{np.round(character.vertices[near].mean(axis=0), 3).tolist()}, ends the head region there "
            "(close the gap in the mesh for this edit)")


def head_patch(
    character: Character,
    scalp: Scalp,
    margin_rings: int | None = None,
    frame: HeadFrame | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A disk-shaped patch of the head around the scalp.

    The scalp's faces, grown ``margin_rings`` times by every head face (three head-dominant
    vertices, :attr:`.body.head_frame.HeadFrame.head_vertices`) of the scalp's shell, clear of
    gaps in the mesh (:func:`clear_of_gaps`), sharing a vertex with the patch, then made a disk
    (holes filled, pinch vertices repaired; :func:`~hairport.solver.mesh.topology.repair_disk`);
    fewer rings where that is no disk.

    Parameters
    ----------
    character : Character
    scalp : Scalp
        From :func:`.scalp.extract_scalp` on this character.
    margin_rings : int, optional
        >= 0; 0 gives the scalp itself. Default :func:`default_margin_rings` (6 on MakeHuman).
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
        Negative ``margin_rings``, or a patch that cannot be made a disk even with no margin
        (``mesh_hole``, ``not_manifold``, ``not_a_disk``).
    """
    frame = frame or head_frame(character)
    if margin_rings is None:
        margin_rings = default_margin_rings(character, scalp, frame)
    if margin_rings < 0:
        raise InputError("margin_rings must be >= 0", code="bad_option")
    faces = character.faces
    shell = np.zeros(len(faces), dtype=bool)
    shell[scalp.faces] = True
    shell = shell_of(faces, shell)
    allowed = shell & frame.head_vertices[faces].all(axis=1) & clear_of_gaps(character, scalp, shell)
    weight = np.zeros(len(faces))
    weight[scalp.faces] = 1.0
    scalp_region = weight > 0
    shell_faces = np.flatnonzero(shell)
    skin = faces[shell_faces]
    adjacency = face_adjacency(skin)
    # the widest margin, up to margin_rings, that gives a disk: a gap in the mesh the
    # margin would reach around (an eye socket near the brows) takes rings off
    for rings in range(margin_rings, -1, -1):
        region = scalp_region.copy()
        for _ in range(rings):
            touched = np.zeros(character.n_vertices, dtype=bool)
            touched[faces[region].ravel()] = True
            region |= allowed & touched[faces].any(axis=1)
        disk = np.zeros(len(faces), dtype=bool)
        disk[shell_faces[repair_disk(skin, region[shell_faces], adjacency, weight[shell_faces], "head patch")]] = True
        if is_disk(submesh(faces, np.flatnonzero(disk))[1]):
            break
    else:
        check_region_disk(character, disk, shell, "head patch")
    face_ids = np.flatnonzero(disk).astype(np.int64)
    vertices, triangles = submesh(faces, face_ids)
    return vertices, triangles, face_ids
