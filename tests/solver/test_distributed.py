"""The fine level in chunks solved elsewhere (solver/distributed.py, on solver/adaptation/fine/fine_chunks.py):
a runner that saves the level's inputs, then solves runs of strands from the artifact, the target and
those inputs alone, gives the in-process result bit for bit, with and without a hairline edit."""

import numpy as np
import pytest

from hairport.solver import InputError, pipeline
from hairport.solver.artifact import load_adaptable, save_adaptable
from hairport.solver.distributed import FineInputs, solve_fine_chunk
from hairport.solver.hairline.edit import HairlineEdit
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import PRESETS, build_character


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """Average female -> heavy male, a 120-strand "short" groom, 20 guides; the artifact as a worker loads it."""
    source = build_character(PRESETS["average-female"])
    target = build_character(PRESETS["heavy-male"])
    hair = generate_groom(source, "short", 120, 30, seed=1)
    adaptable = pipeline.preprocess(source, hair, pipeline.PreprocessOptions(guides=20))
    path = tmp_path_factory.mktemp("artifact") / "groom.hpa"
    save_adaptable(adaptable, path)
    return adaptable, target, path


class ChunksElsewhere:
    """A fine runner that solves each chunk as another process would: from the saved inputs, the artifact
    loaded again from its file and the unprepared target."""

    def __init__(self, artifact_path, target, options, folder, strands_per_chunk):
        self.artifact_path, self.target, self.options = artifact_path, target, options
        self.folder, self.strands_per_chunk = folder, strands_per_chunk
        self.chunks = []

    def __call__(self, level, progress, should_stop):
        path = self.folder / "inputs.npz"
        level.inputs.save(path)
        other = load_adaptable(self.artifact_path)
        inputs = FineInputs.load(path, other.hair, other.multiscale.guides)
        strands = len(level.counts)
        bounds = list(range(0, strands, self.strands_per_chunk)) + [strands]
        pieces, reports = [], []
        for first, stop in zip(bounds[:-1], bounds[1:]):
            points, report = solve_fine_chunk(other, self.target, self.options, inputs, first, stop)
            pieces.append(points)
            reports.append(report)
            self.chunks.append((first, stop))
        return np.concatenate(pieces), reports, 1


@pytest.mark.parametrize("hairline, spacing", [(None, 0.0), (HairlineEdit(preset="receding", amount=0.5), 0.0),
                                               (None, 0.3)], ids=["plain", "hairline", "spacing"])
def test_chunks_solved_elsewhere_equal_the_in_process_solve_bit_for_bit(case, tmp_path, hairline, spacing):
    adaptable, target, artifact_path = case
    options = pipeline.RetargetOptions(method="multiscale", hairline=hairline, spacing=spacing)
    here = pipeline.retarget(adaptable, target, options)
    runner = ChunksElsewhere(artifact_path, target, pipeline.RetargetOptions(method="multiscale", spacing=spacing),
                             tmp_path, 37)
    elsewhere = pipeline.retarget(load_adaptable(artifact_path), target, options, fine_runner=runner)
    assert len(runner.chunks) == 3  # 100 normal strands in runs of 37
    assert np.array_equal(here.hair.points, elsewhere.hair.points)
    assert here.metrics["penetrating_particles"] == elsewhere.metrics["penetrating_particles"] == 0
    assert [r.iterations for r in elsewhere.solve.fine] != []
    moved = np.linalg.norm(here.hair.points - here.initial.points, axis=1).max()
    assert moved > 1e-3  # the fine level did work: equality is not of untouched points


def test_a_chunk_outside_the_normal_strands_is_refused(case):
    adaptable, target, _ = case
    options = pipeline.RetargetOptions(method="multiscale")
    inputs = FineInputs(np.zeros((3, 3)), np.zeros((adaptable.hair.n_particles, 3)))
    with pytest.raises(InputError) as error:
        solve_fine_chunk(adaptable, target, options, inputs, 5, 500)
    assert error.value.code == "bad_fine_chunk" and "100 normal strands" in str(error.value)
