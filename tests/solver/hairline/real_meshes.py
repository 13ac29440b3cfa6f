"""Character meshes as they come from games and scans, for the hairline tests: a finer
triangulation of a character, and a groom whose strands sit off the skin."""

import numpy as np
import scipy.sparse as sp

from hairport.solver.mesh.query import MeshQuery
from hairport.solver.mesh.topology import subdivide
from hairport.solver.mesh.triangles import face_frames
from hairport.solver.model.character import Character
from hairport.solver.synthetic.groom import generate_groom

#: how far off the skin :func:`lifted_groom` moves the strands (m), uniformly per strand
LIFT_M = (0.002, 0.005)


def subdivided(character: Character) -> Character:
    """The character with every triangle split in four at its edges' midpoints (the same
    surface, four times the faces), each midpoint with the mean skin weights of its edge."""
    stacked = np.hstack([character.vertices, character.weights.toarray()])
    points, triangles, _ = subdivide(stacked, character.faces, np.zeros(0, np.int64))
    return Character(points[:, :3], triangles, character.skeleton, sp.csr_matrix(points[:, 3:]),
                     f"{character.name} subdivided")


def lifted_groom(body: Character, strands: int, particles: int, style: str = "short"):
    """A groom on ``body`` (seed 0) with each strand moved 2-5 mm along its root's face normal."""
    hair = generate_groom(body, style, strands, particles, seed=0)
    found = MeshQuery(body.vertices, body.faces).signed_distance(hair.points[hair.roots])
    normals = face_frames(body.vertices, body.faces, found.faces)[0][:, :, 0]
    lift = np.random.default_rng(0).uniform(*LIFT_M, hair.n_strands)
    return hair.with_points(hair.points + np.repeat(normals * lift[:, None], hair.counts, axis=0))
