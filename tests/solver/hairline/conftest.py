"""The MakeHuman head the hairline tests share: the average female with the roots of a
300-strand "short" groom on her (seed 0), their scalp, and the scalp's parameterized chart;
and her bust (eyes and teeth as separate shells, cut open at the chest) with the same roots."""

import numpy as np
import pytest

from hairport.solver.body.head_frame import head_frame
from hairport.solver.hairline.relocation import scalp_chart
from hairport.solver.hairline.scalp import extract_scalp
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.mesh.triangles import barycentric_coordinates
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import PRESETS, build_character
from hairport.solver.synthetic.makehuman.bust import build_bust, keep_faces


@pytest.fixture(scope="session")
def character():
    return build_character(PRESETS["average-female"])


@pytest.fixture(scope="session")
def frame(character):
    return head_frame(character)


@pytest.fixture(scope="session")
def query(character):
    return MeshQuery(character.vertices, character.faces)


@pytest.fixture(scope="session")
def roots(character, query):
    """(S, 3) root positions and (S,) faces holding them (8 particles per strand)."""
    hair = generate_groom(character, "short", 300, 8, seed=0)
    points = hair.points[hair.roots]
    return points, query.signed_distance(points).faces


@pytest.fixture(scope="session")
def scalp(character, roots, frame):
    return extract_scalp(character, roots[1], frame)


@pytest.fixture(scope="session")
def root_anchors(character):
    """(faces, barycentric, points) of the roots of the same groom grown with 4 particles per strand."""
    hair = generate_groom(character, "short", 300, 4, seed=0)
    points = hair.points[hair.roots]
    found = MeshQuery(character.vertices, character.faces).signed_distance(points)
    weights = barycentric_coordinates(found.closest, character.vertices[character.faces[found.faces]])
    return found.faces, weights, points


@pytest.fixture(scope="session")
def scalp_setup(character, root_anchors):
    """The refined scalp of ``root_anchors`` in its harmonic head chart."""
    return scalp_chart(character, root_anchors[0])


@pytest.fixture(scope="session")
def bust():
    return build_bust("average-female")


@pytest.fixture(scope="session")
def bust_roots(bust, roots):
    """(S,) faces of the bust holding the roots of ``roots``."""
    return MeshQuery(bust.vertices, bust.faces).signed_distance(roots[0]).faces


@pytest.fixture(scope="session")
def gapped(character, scalp, frame, root_anchors):
    """The average female with a gap in her forehead (the faces around the vertex 1.5 cm below
    the middle of the front hairline removed) and the roots of ``root_anchors`` on her:
    ``(character, gap centre (3,), root faces, root barycentric)``."""
    middle = character.vertices[scalp.vertices[scalp.front[len(scalp.front) // 2]]]
    gap = int(np.argmin(np.linalg.norm(character.vertices - (middle - 0.015 * frame.up), axis=1)))
    keep = ~(character.faces == gap).any(axis=1)
    holed = keep_faces(character, keep)
    found = MeshQuery(holed.vertices, holed.faces).signed_distance(root_anchors[2])
    weights = barycentric_coordinates(found.closest, holed.vertices[holed.faces[found.faces]])
    return holed, character.vertices[gap], found.faces, weights
