"""Fixtures shared by the hairline test modules: the MakeHuman average female and the scalp
of a 300-strand "short" groom on her (seed 0)."""

import pytest

from hairport.solver.body.head_frame import head_frame
from hairport.solver.hairline.scalp import extract_scalp
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import PRESETS, build_character


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
    """(S, 3) root positions and (S,) faces holding them."""
    hair = generate_groom(character, "short", 300, 8, seed=0)
    points = hair.points[hair.roots]
    return points, query.signed_distance(points).faces


@pytest.fixture(scope="session")
def scalp(character, roots, frame):
    return extract_scalp(character, roots[1], frame)
