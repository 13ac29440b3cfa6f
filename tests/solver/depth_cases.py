"""Grooms sunk into their bodies, open busts, and a body that traps hair: the cases of the
"penetration-free at any depth" tests (pipeline, command line, worker, quality)."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import trimesh

from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.character import Character
from hairport.solver.model.hair import Hair
from hairport.solver.synthetic.makehuman.bust import keep_faces

__all__ = ["TOY_CHEST_Y_M", "chest_cut", "keep_faces", "sunk", "trap", "with_blocks"]

#: the toy bust's cut (m along Y): across the chest, 13 cm under the shoulders' top
TOY_CHEST_Y_M = 1.35
#: the trap: a stack of thin plates over the crown, this far above it (m), this many, this thick
#: (m), with cracks this wide between them (m): wider than the inside test's side probe, far
#: narrower than the last push-out round's clearance (eps_c / 32 = 15.6 um)
TRAP_FLOOR_M = 0.02
TRAP_PLATES = 30
TRAP_PLATE_M = 1e-3
TRAP_CRACK_M = 1e-5
#: the plates' half-width (m) around the crown
TRAP_HALF_WIDTH_M = 0.03
#: straight strands through the trap: particles, length (m), root offsets (m) from the crown in x, z
TRAP_PARTICLES = 31
TRAP_LENGTH_M = 0.075
TRAP_ROOTS_XZ = ((0.0, 0.0), (0.01, 0.0), (-0.01, 0.005), (0.0, -0.01))


def sunk(hair: Hair, depth: float) -> Hair:
    """The groom moved down (-Y) by ``depth`` (m): into its head and shoulders."""
    return hair.with_points(hair.points - np.array([0.0, depth, 0.0]))


def chest_cut(reference: Character, height: float) -> np.ndarray:
    """(F,) bool: the faces of ``reference`` with no vertex below ``height`` (m along Y); the
    same faces cut from every body of its topology make busts of one topology."""
    return ~(reference.vertices[reference.faces, 1] < height).any(axis=1)


def with_blocks(character: Character, blocks: list[tuple[np.ndarray, np.ndarray]], bone: str = "head") -> Character:
    """``character`` with closed boxes ``(lower corner, upper corner)`` (m) appended as extra
    shells, their vertices skinned to ``bone``."""
    vertices, faces, n = [character.vertices], [character.faces], character.n_vertices
    for lower, upper in blocks:
        box = trimesh.creation.box(bounds=[lower, upper])
        vertices.append(np.asarray(box.vertices, dtype=np.float64))
        faces.append(np.asarray(box.faces, dtype=np.int64) + n)
        n += len(box.vertices)
    extra = n - character.n_vertices
    index = character.skeleton.index(bone)
    weights = sp.vstack([character.weights, sp.csr_matrix(
        (np.ones(extra), (np.arange(extra), np.full(extra, index))), shape=(extra, character.skeleton.n_bones))])
    return Character(np.vstack(vertices), np.vstack(faces), character.skeleton, weights.tocsr(),
                     f"{character.name}-trap")


def trap(character: Character) -> tuple[Character, Hair]:
    """A body that traps hair, and hair it traps.

    A stack of :data:`TRAP_PLATES` plates over the crown, 1 mm thick and :data:`TRAP_CRACK_M`
    apart (a layered prop, shells exported on top of one another), and straight strands rooted
    at the crown standing up through it. A particle inside a plate can leave it only into a
    crack, narrower than any push's clearance: the solvers' constraints and every push-out
    round put it into the next plate, and back.
    """
    crown = character.vertices[np.argmax(character.vertices[:, 1])]
    half = np.array([TRAP_HALF_WIDTH_M, 0.0, TRAP_HALF_WIDTH_M])
    floors = TRAP_FLOOR_M + np.arange(TRAP_PLATES) * (TRAP_PLATE_M + TRAP_CRACK_M)
    body = with_blocks(character, [(crown + [0.0, y, 0.0] - half, crown + [0.0, y + TRAP_PLATE_M, 0.0] + half)
                                   for y in floors])
    query = MeshQuery(character.vertices, character.faces)
    rise = np.linspace(0.0, TRAP_LENGTH_M, TRAP_PARTICLES)
    strands = []
    for dx, dz in TRAP_ROOTS_XZ:
        root = query.signed_distance((crown + [dx, TRAP_LENGTH_M, dz])[None]).closest[0]
        strands.append(root + np.outer(rise, [0.0, 1.0, 0.0]))
    offsets = np.arange(0, TRAP_PARTICLES * len(strands) + 1, TRAP_PARTICLES)
    return body, Hair(np.vstack(strands), offsets)
