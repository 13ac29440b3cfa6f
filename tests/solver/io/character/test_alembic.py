"""An Alembic animated mesh as frames: positions sampled over time under an animated transform, its clockwise faces
turned to hairport's winding, times between samples interpolated; still, damaged and mismatched archives refused."""

from __future__ import annotations

import numpy as np
import pytest

from hairport.solver.io.character.alembic import read_alembic_frames
from hairport.solver.io.character.frames import read_character_frames
from hairport.solver.mesh.query import MeshQuery
from hairport.solver.model.errors import InputError
from hairport.solver.model.frame_range import FrameRange
from hairport.solver.synthetic import toy
from tests.solver.synthetic.toy_fixtures import PRESET_B

LIMITS = {"max_vertices": 10**6, "max_faces": 10**6, "mesh_name": None}
#: the transform's motion along X per sample (m)
DRIFT_M = 0.02


@pytest.fixture(scope="module")
def bodies():
    source = toy.toy_character()
    other = toy.toy_character(**PRESET_B)
    return source, [source.vertices + t * (other.vertices - source.vertices) for t in np.linspace(0, 1, 3)]


def animated_archive(path, faces, frames, *, start_s=0.0, still=False) -> None:
    """One mesh under an Xform, ``frames`` sampled every 1/24 s from ``start_s``, the faces wound clockwise."""
    import imath
    from alembic3d import Abc, AbcCoreAbstract, AbcGeom

    archive = Abc.OArchive(str(path))
    sampling = archive.addTimeSampling(AbcCoreAbstract.TimeSampling(1.0 / 24.0, start_s))
    xform = AbcGeom.OXform(archive.getTop(), "body_xform", sampling)
    mesh = AbcGeom.OPolyMesh(xform, "body", sampling)
    counts = imath.IntArray(len(faces))
    for i in range(len(faces)):
        counts[i] = 3
    clockwise = faces[:, ::-1].ravel()
    indices = imath.IntArray(len(clockwise))
    for i, value in enumerate(clockwise):
        indices[i] = int(value)
    for number, vertices in enumerate(frames[:1] if still else frames):
        positions = imath.V3fArray(len(vertices))
        for i, (x, y, z) in enumerate(vertices):
            positions[i] = imath.V3f(float(x), float(y), float(z))
        mesh.getSchema().set(AbcGeom.OPolyMeshSchemaSample(positions, indices, counts))
        sample = AbcGeom.XformSample()
        sample.setTranslation(imath.V3d(DRIFT_M * number, 0.0, 0.0))
        xform.getSchema().set(sample)


def test_an_animated_mesh_is_read_at_its_frames(tmp_path, bodies):
    source, frames = bodies
    animated_archive(tmp_path / "body.abc", source.faces, frames)
    read = read_character_frames([tmp_path / "body.abc"], FrameRange.parse("0:2"), units="m")
    assert read.times == [0.0, 1.0, 2.0] and read.units == "m"
    for number, (character, vertices) in enumerate(zip(read.characters, frames)):
        assert np.abs(character.vertices - vertices - [DRIFT_M * number, 0.0, 0.0]).max() < 1e-6
        assert np.array_equal(character.faces, source.faces) and character.skeleton is None
    # the winding is hairport's: a point inside the body is inside the mesh read
    query = MeshQuery(read.characters[0].vertices, read.characters[0].faces)
    centre = source.vertices[source.vertices[:, 1] > 1.5].mean(axis=0)[None]  # inside the head
    assert query.signed_distance(centre).distance[0] < 0
    inverted = MeshQuery(read.characters[0].vertices, read.characters[0].faces[:, ::-1])
    assert inverted.signed_distance(centre).distance[0] > 0  # the sign follows the winding
    halfway = read_alembic_frames(tmp_path / "body.abc", [0.5 / 24.0], **LIMITS)[0]
    middle = 0.5 * (frames[0] + frames[1])
    assert np.abs(halfway.vertices - middle).max() < 0.011  # positions between samples, the transform's nearest


def test_a_still_or_short_archive_is_refused(tmp_path, bodies):
    source, frames = bodies
    animated_archive(tmp_path / "still.abc", source.faces, frames, still=True)
    animated_archive(tmp_path / "late.abc", source.faces, frames, start_s=1.0)
    (tmp_path / "broken.abc").write_bytes(b"Ogawa" + bytes(200))
    for name, code in (("still.abc", "not_animated"), ("late.abc", "bad_frames"), ("broken.abc", "bad_header")):
        with pytest.raises(InputError) as caught:
            read_character_frames([tmp_path / name], FrameRange.parse("0:2"))
        assert caught.value.code == code, caught.value.problem


def test_an_archive_read_as_one_body_is_its_first_sample(tmp_path, bodies):
    """A still read (an upload, a single target): the first sample through its transform, Alembic's winding turned,
    no units (Alembic records none); an animated archive's later samples are not read."""
    from hairport.solver.io.character.load import read_character

    source, frames = bodies
    animated_archive(tmp_path / "still.abc", source.faces, frames, still=True)
    animated_archive(tmp_path / "late.abc", source.faces, frames, start_s=1.0)
    for name in ("still.abc", "late.abc"):
        character, units = read_character(tmp_path / name)
        assert units is None and np.array_equal(character.faces, source.faces)
        assert np.abs(character.vertices - frames[0]).max() < 1e-6
    (tmp_path / "broken.abc").write_bytes(b"Ogawa" + bytes(200))
    with pytest.raises(InputError) as caught:
        read_character(tmp_path / "broken.abc")
    assert caught.value.code == "bad_header"
