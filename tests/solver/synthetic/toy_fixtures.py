"""The toy characters and grooms the synthetic and render tests share."""

from __future__ import annotations

from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.character import Character
from hairport.solver.synthetic.groom import generate_groom

#: a second toy body: larger head, thicker and shorter neck, wider shoulders
PRESET_B = dict(head_scale=(1.1, 0.95, 1.05), neck_radius=0.065, shoulder_width=0.44, neck_length=0.11)
#: the grooms grown on the toy: strands, particles per strand, seed
N_STRANDS = 200
PARTICLES = 24
GROOM_SEED = 3


def toy_grooms(character: Character, query: MeshQuery, styles) -> dict:
    """One groom per style on ``character``, with the shared sizes and seed."""
    return {style: generate_groom(character, style, N_STRANDS, PARTICLES, seed=GROOM_SEED, query=query)
            for style in styles}
