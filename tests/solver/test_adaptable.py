"""The adaptable hairstyle: source-only operators built once and shared by every retarget."""

import numpy as np
import pytest

from hairport.solver.options import PreprocessOptions
from hairport.solver.pipeline import preprocess
from hairport.solver.synthetic import toy
from hairport.solver.synthetic.groom import generate_groom


@pytest.fixture(scope="module")
def adaptable():
    source = toy.toy_character()
    return preprocess(source, generate_groom(source, "short", 24, 6, seed=3), PreprocessOptions(guides=6, k=3))


def test_operators_are_built_once(adaptable):
    for name in ("neighbours", "shape_model", "coarse_model", "fine_source", "strand_laplacian"):
        assert getattr(adaptable, name) is getattr(adaptable, name), name


def test_operator_sizes(adaptable):
    hair = adaptable.hair
    assert adaptable.neighbours.index.shape == (hair.n_particles, 3)
    assert adaptable.shape_model.K.shape == (hair.n_particles, hair.n_particles)
    assert adaptable.strand_laplacian.shape == (hair.n_particles, hair.n_particles)
    guides = adaptable.multiscale.guides
    assert len(guides) == 6 and adaptable.coarse_model.K.shape[0] == int(hair.counts[guides].sum())
    assert len(adaptable.fine_source.strands) == hair.n_strands - 6
    assert np.intersect1d(adaptable.fine_source.strands, guides).size == 0
    assert adaptable.bone_names == adaptable.source.skeleton.names
    assert set(adaptable.timings) == {"anchors", "guides", "neighbours"}
