"""The shape carry after Eq. 2-6 (solver/transfer/carry.py): the minimiser it claims, its two limits, a
reflexive fixed point, roots kept."""

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from hairport.solver.mesh.polyline import rest_lengths
from hairport.solver.transfer.carry import carry_shapes


def strands(seed=0, n_strands=40):
    rng = np.random.default_rng(seed)
    counts = rng.integers(2, 30, n_strands)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    source = np.cumsum(rng.normal(scale=0.004, size=(offsets[-1], 3)), axis=0)
    anchored = source * 1.1 + rng.normal(scale=2e-3, size=source.shape)
    fixed = np.zeros(offsets[-1], dtype=bool)
    fixed[offsets[:-1]] = True
    return source, anchored, offsets, fixed


def minimiser(anchored, source, offsets, fixed, length):
    """The module's energy minimised by a sparse solve of its normal equations (the reference)."""
    n = len(source)
    rest = rest_lengths(source, anchored, offsets)
    seg = np.flatnonzero(rest > 0)
    vector = source[seg + 1] - source[seg]
    vector *= (rest[seg] / np.linalg.norm(vector, axis=1))[:, None]
    weight = (length / rest[seg]) ** 2
    D = sp.csr_matrix((np.tile([-1.0, 1.0], len(seg)), (np.repeat(np.arange(len(seg)), 2),
                                                         np.stack([seg, seg + 1], 1).ravel())), shape=(len(seg), n))
    A = (D.T @ sp.diags(weight) @ D + sp.identity(n)).tocsr()
    b = D.T @ (weight[:, None] * vector) + anchored
    free, kept = np.flatnonzero(~fixed), np.flatnonzero(fixed)
    result = anchored.copy()
    result[free] = spla.spsolve(A[free][:, free].tocsc(), b[free] - A[free][:, kept] @ anchored[kept])
    return result


def test_it_is_the_minimiser_and_keeps_fixed_particles_including_one_inside_a_strand():
    source, anchored, offsets, fixed = strands()
    fixed[5] = True  # not a root: a fixed particle in the middle of a strand
    carried = carry_shapes(anchored, source, offsets, fixed, 0.05)
    np.testing.assert_allclose(carried, minimiser(anchored, source, offsets, fixed, 0.05), rtol=0, atol=1e-12)
    assert np.array_equal(carried[fixed], anchored[fixed])


def test_the_source_is_a_fixed_point_and_zero_length_carries_nothing():
    source, anchored, offsets, fixed = strands(1)
    assert np.abs(carry_shapes(source, source, offsets, fixed, 0.05) - source).max() < 1e-12
    assert carry_shapes(anchored, source, offsets, fixed, 0.0) is anchored


def test_short_lengths_keep_the_anchoring_and_long_ones_the_scaled_source_shape():
    source, anchored, offsets, fixed = strands(2)
    near = carry_shapes(anchored, source, offsets, fixed, 1e-7)
    assert np.abs(near - anchored).max() < 1e-6
    far = carry_shapes(anchored, source, offsets, fixed, 100.0)
    rest = rest_lengths(source, anchored, offsets)
    for s in range(len(offsets) - 1):
        rows = slice(offsets[s], offsets[s + 1])
        segment = np.arange(offsets[s], offsets[s + 1] - 1)
        unit = (source[segment + 1] - source[segment]) / np.linalg.norm(source[segment + 1] - source[segment],
                                                                          axis=1)[:, None]
        laid = anchored[offsets[s]] + np.concatenate([[np.zeros(3)], np.cumsum(unit * rest[segment][:, None], 0)])
        np.testing.assert_allclose(far[rows], laid, rtol=0, atol=1e-5)  # the root plus the scaled source segments


def test_runs_of_strands_solved_apart_give_the_whole_solve(monkeypatch):
    from hairport.solver.transfer import carry

    source, anchored, offsets, fixed = strands(3, n_strands=60)
    whole = carry_shapes(anchored, source, offsets, fixed, 0.05)
    monkeypatch.setattr(carry, "CARRY_CHUNK", 37)  # runs of a few strands; a strand longer than a run alone
    assert np.abs(carry_shapes(anchored, source, offsets, fixed, 0.05) - whole).max() < 1e-15
