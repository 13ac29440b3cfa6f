"""The adaptable-hairstyle artifact (.hpa): bit-for-bit round trip, refusal of foreign or damaged files."""

import json
import zipfile

import numpy as np
import pytest

from hairport.solver import artifact, pipeline
from hairport.solver.model.character import Character
from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import Hair, HairAttribute
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import PRESETS, build_character
from tests.solver.hair_shapes import outward_strands, sphere_character


@pytest.fixture(scope="module")
def case():
    source = build_character(PRESETS["average-female"])
    target = build_character(PRESETS["slim-tall-female"])
    hair = generate_groom(source, "short", 40, 12, seed=3)
    adaptable = pipeline.preprocess(source, hair, pipeline.PreprocessOptions(guides=12))
    return source, target, hair, adaptable


@pytest.fixture(scope="module")
def saved(case, tmp_path_factory):
    path = tmp_path_factory.mktemp("artifact") / "groom.hpa"
    artifact.save_adaptable(case[3], path)
    return path


def test_retarget_from_saved_artifact_equals_retarget_from_memory_bit_for_bit(case, saved):
    _, target, hair, adaptable = case
    options = pipeline.RetargetOptions(max_iterations=8, workers=1)
    from_memory = pipeline.retarget(adaptable, target, options)
    loaded = artifact.load_adaptable(saved)
    from_disk = pipeline.retarget(loaded, target, options)
    assert np.array_equal(from_memory.hair.points, from_disk.hair.points)
    assert np.array_equal(loaded.hair.points, hair.points) and np.array_equal(loaded.hair.offsets, hair.offsets)
    assert np.array_equal(loaded.multiscale.guides, adaptable.multiscale.guides)
    assert len(loaded.multiscale.guides) == 12
    assert loaded.options == adaptable.options
    assert from_memory.metrics == from_disk.metrics


def test_saving_leaves_no_temporary_file(saved):
    assert sorted(p.name for p in saved.parent.iterdir()) == ["groom.hpa"]


def rewrite_meta(src, dst, change):
    with np.load(src) as archive:
        arrays = {name: archive[name] for name in archive.files}
    meta = json.loads(arrays["meta"].tobytes().decode())
    change(meta, arrays)
    arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    with open(dst, "wb") as out:
        np.savez(out, **arrays)


def test_other_format_version_is_refused(saved, tmp_path):
    other = tmp_path / "old.hpa"
    rewrite_meta(saved, other, lambda meta, arrays: meta.update(format_version=artifact.FORMAT_VERSION + 1))
    with pytest.raises(InputError, match="format version 4.*reads versions 1, 2, 3") as caught:
        artifact.load_adaptable(other)
    assert caught.value.code == "artifact_version"


def as_version_1(meta, arrays):
    """The arrays as format version 1 wrote them: int64 indices, a frame offset row per particle."""
    for name in ("anchor_bone", "anchor_face", "guide_neighbour_index", "fine_neighbour_index"):
        arrays[name] = arrays[name].astype(np.int64)
    fallback = arrays["anchor_fallback"]
    full = np.zeros((len(fallback), 3))
    full[fallback] = arrays["anchor_frame_offset"]
    arrays["anchor_frame_offset"] = full
    meta["format_version"] = 1
    meta["digest"] = artifact._digest({name: value for name, value in arrays.items() if name != "meta"})


def test_version_1_artifacts_are_read_and_retarget_bit_for_bit_like_version_2(case, saved, tmp_path):
    _, target, _, adaptable = case
    old = tmp_path / "v1.hpa"
    rewrite_meta(saved, old, as_version_1)
    with np.load(old) as archive:
        assert archive["anchor_face"].dtype == np.int64 and archive["anchor_frame_offset"].shape == (
            adaptable.hair.n_particles, 3)
    loaded, current = artifact.load_adaptable(old), artifact.load_adaptable(saved)
    for name in ("bone", "face", "barycentric", "eta", "frame_offset", "fallback"):
        assert np.array_equal(getattr(loaded.anchors, name), getattr(current.anchors, name)), name
        assert getattr(loaded.anchors, name).dtype == getattr(current.anchors, name).dtype, name
    assert loaded.multiscale.fine_neighbours.index.dtype == np.int32
    options = pipeline.RetargetOptions(max_iterations=8, workers=1)
    assert np.array_equal(pipeline.retarget(loaded, target, options).hair.points,
                          pipeline.retarget(adaptable, target, options).hair.points)


def test_compact_indices_and_only_the_fallback_frame_offsets_are_stored(case, saved):
    adaptable = case[3]
    with np.load(saved) as archive:
        assert archive["anchor_bone"].dtype == np.int16 and archive["anchor_face"].dtype == np.int32
        assert archive["fine_neighbour_index"].dtype == archive["guide_neighbour_index"].dtype == np.int32
        assert archive["anchor_frame_offset"].shape == (int(adaptable.anchors.fallback.sum()), 3)
        assert json.loads(archive["meta"].tobytes())["format_version"] == artifact.FORMAT_VERSION == 3


def test_attributes_are_kept_in_the_artifact_and_come_out_of_the_retarget_unchanged(case, tmp_path):
    source, target, hair, _ = case
    rng = np.random.default_rng(5)
    attributes = {
        "uv": HairAttribute(rng.random((hair.n_particles, 2)).astype(np.float32), "vertex", "texcoord"),
        "groom_group_id": HairAttribute(rng.integers(0, 4, hair.n_strands).astype(np.int32), "strand"),
    }
    styled = Hair(hair.points, hair.offsets, hair.thickness, hair.color, attributes)
    path = tmp_path / "styled.hpa"
    artifact.save_adaptable(pipeline.preprocess(source, styled, pipeline.PreprocessOptions(guides=12)), path)
    loaded = artifact.load_adaptable(path)
    result = pipeline.retarget(loaded, target, pipeline.RetargetOptions(max_iterations=4, workers=1)).hair
    assert list(result.attributes) == ["uv", "groom_group_id"]
    for name, attribute in attributes.items():
        assert result.attributes[name].domain == attribute.domain and result.attributes[name].role == attribute.role
        assert result.attributes[name].values.dtype == attribute.values.dtype
        np.testing.assert_array_equal(result.attributes[name].values, attribute.values)
    assert np.abs(result.points - hair.points).max() > 1e-3  # the positions did change


def test_a_version_2_artifact_without_attributes_still_loads(saved, tmp_path):
    older = tmp_path / "v2.hpa"

    def as_version_2(meta, arrays):
        meta["format_version"] = 2
        meta.pop("hair_attributes")

    rewrite_meta(saved, older, as_version_2)
    assert artifact.load_adaptable(older).hair.attributes == {}


def test_altered_arrays_are_refused(saved, tmp_path):
    altered = tmp_path / "altered.hpa"

    def nudge(meta, arrays):
        arrays["hair_points"] = arrays["hair_points"] + 1e-3

    rewrite_meta(saved, altered, nudge)
    with pytest.raises(InputError, match="corrupted") as caught:
        artifact.load_adaptable(altered)
    assert caught.value.code == "bad_artifact"


@pytest.mark.parametrize("damage", ["truncate", "flip", "empty", "not-a-zip", "foreign-npz"])
def test_damaged_files_are_refused(saved, tmp_path, damage):
    data = saved.read_bytes()
    bad = tmp_path / f"{damage}.hpa"
    if damage == "truncate":
        bad.write_bytes(data[: len(data) // 2])
    elif damage == "flip":
        middle = bytearray(data)
        middle[len(data) // 2] ^= 0xFF
        bad.write_bytes(bytes(middle))
    elif damage == "empty":
        bad.write_bytes(b"")
    elif damage == "not-a-zip":
        bad.write_text("hello")
    else:
        with open(bad, "wb") as out:
            np.savez(out, points=np.zeros((3, 3)))
    with pytest.raises(InputError) as caught:
        artifact.load_adaptable(bad)
    assert caught.value.code == "bad_artifact"
    assert str(bad) in str(caught.value)


def test_missing_artifact_is_file_not_found(tmp_path):
    with pytest.raises(FileNotFoundError):
        artifact.load_adaptable(tmp_path / "nothing.hpa")


def test_artifact_is_a_plain_zip_of_arrays(saved):
    with zipfile.ZipFile(saved) as archive:
        names = set(archive.namelist())
    assert {"meta.npy", "hair_points.npy", "guides.npy", "fine_neighbour_index.npy"} <= names


def test_artifact_without_a_fine_level_round_trips(case, tmp_path):
    """Every strand a guide: the fine-level arrays are empty."""
    source, target, hair, _ = case
    adaptable = pipeline.preprocess(source, hair, pipeline.PreprocessOptions(guides=1000))
    assert adaptable.multiscale.fine_neighbours.index.shape == (0, 5)
    artifact.save_adaptable(adaptable, tmp_path / "all-guides.hpa")
    loaded = artifact.load_adaptable(tmp_path / "all-guides.hpa")
    assert np.array_equal(loaded.multiscale.guides, np.arange(hair.n_strands))


def test_rows_with_fewer_than_k_neighbours_round_trip(tmp_path):
    """A long strand beside two short ones: its particles find 4 of k = 5 neighbours, the
    file keeps the padding and zero weights, and the retarget from disk equals the one in memory."""
    source, target = sphere_character(), sphere_character(scale=(1.1, 1.0, 1.05))
    long = outward_strands(source, n_strands=1, n_points=700, seed=1)
    short = outward_strands(source, n_strands=2, n_points=2, seed=2)
    hair = pipeline.Hair.from_strands([long.strand(0), short.strand(0), short.strand(1)])
    adaptable = pipeline.preprocess(source, hair, pipeline.PreprocessOptions(guides=3))
    weight = adaptable.multiscale.guide_neighbours.weight
    assert (np.count_nonzero(weight[:700], axis=1) == 4).all()
    np.testing.assert_allclose(weight.sum(axis=1), 1.0, atol=1e-12)
    artifact.save_adaptable(adaptable, tmp_path / "long.hpa")
    loaded = artifact.load_adaptable(tmp_path / "long.hpa")
    assert np.array_equal(loaded.multiscale.guide_neighbours.index, adaptable.multiscale.guide_neighbours.index)
    options = pipeline.RetargetOptions(max_iterations=5, workers=1)
    from_memory, from_disk = pipeline.retarget(adaptable, target, options), pipeline.retarget(loaded, target, options)
    assert np.array_equal(from_memory.hair.points, from_disk.hair.points)
    assert from_memory.metrics["penetrating_particles"] == 0


def test_the_grooms_frame_and_input_report_travel_with_the_artifact(case, tmp_path):
    source, _, hair, _ = case
    from hairport.solver.model.frame import InputFrame

    frame = InputFrame("mm", "z", "-y")
    report = {"units": {"hair": "mm"}, "warnings": ["3 of 40 roots sit more than 1 mm off the source body"]}
    adaptable = pipeline.preprocess(source, hair, pipeline.PreprocessOptions(guides=12), frame=frame,
                                    input_report=report)
    assert (adaptable.frame, adaptable.input_report) == (frame, report)
    path = tmp_path / "framed.hpa"
    artifact.save_adaptable(adaptable, path)
    loaded = artifact.load_adaptable(path)
    assert loaded.frame == frame and loaded.input_report == report
    # an artifact written before frames were recorded reads as hairport's own frame
    older = tmp_path / "older.hpa"
    rewrite_meta(path, older, lambda meta, arrays: [meta.pop("input_frame"), meta.pop("input_report")])
    assert (artifact.load_adaptable(older).frame, artifact.load_adaptable(older).input_report) == (InputFrame(), {})


def test_a_hairstyle_anchored_by_the_surface_of_a_source_without_a_rig_round_trips(case, tmp_path):
    source, target, hair, _ = case
    bare = Character(source.vertices, source.faces, name="bare")
    adaptable = pipeline.preprocess(bare, hair, pipeline.PreprocessOptions(guides=12))
    loaded = artifact.load_adaptable(artifact.save_adaptable(adaptable, tmp_path / "bare.hpa"))
    assert loaded.source.skeleton is None and loaded.source.weights is None and loaded.bone_names == ()
    assert loaded.options.anchoring == "surface" and (loaded.anchors.bone == -1).all()
    options = pipeline.RetargetOptions(max_iterations=8, workers=1)
    target = Character(target.vertices, target.faces, name="bare target")
    assert np.array_equal(pipeline.retarget(adaptable, target, options).hair.points,
                          pipeline.retarget(loaded, target, options).hair.points)


def test_artifacts_written_before_surface_anchoring_read_as_anchored_by_bones(saved, tmp_path):
    with np.load(saved) as archive:
        arrays = {name: archive[name] for name in archive.files}
    meta = json.loads(arrays["meta"].tobytes())
    del meta["options"]["anchoring"]
    arrays["meta"] = np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8)
    with open(tmp_path / "old.hpa", "wb") as handle:
        np.savez(handle, **arrays)
    assert artifact.load_adaptable(tmp_path / "old.hpa").options.anchoring == "bones"


def test_the_source_scene_reads_the_groom_and_body_in_hairport_frame_as_float32(case, saved, tmp_path):
    source, _, hair, _ = case
    scene = artifact.source_scene(saved)
    assert scene["points"].dtype == np.float32 and scene["body_faces"].dtype == np.uint32
    np.testing.assert_allclose(scene["points"], hair.points, atol=1e-6)
    np.testing.assert_array_equal(scene["offsets"], hair.offsets)
    np.testing.assert_allclose(scene["body_vertices"], source.vertices, atol=1e-6)
    assert "color" not in scene
    (tmp_path / "cut.hpa").write_bytes(saved.read_bytes()[:1000])
    with pytest.raises(InputError) as error:
        artifact.source_scene(tmp_path / "cut.hpa")
    assert error.value.code == "bad_artifact"
