"""Landmark documents (solver/model/landmarks.py): read, refused by name when malformed, brought into hairport's frame."""

import json

import numpy as np
import pytest

from hairport.solver.model.errors import InputError
from hairport.solver.model.frame import InputFrame
from hairport.solver.model.landmarks import MAX_LANDMARKS, MAX_LANDMARKS_FILE_BYTES, LandmarkPairs, read_landmarks

DOCUMENT = {"source": {"nose_tip": [0.0, 1.6, 0.1], "chin": [0.0, 1.5, 0.08], "crown": [0.0, 1.75, 0.0]},
            "target": {"crown": [0.0, 0.0, 1800.0], "nose_tip": [0.0, -100.0, 1650.0], "chin": [0.0, -90.0, 1550.0]}}


def test_a_document_pairs_its_points_by_name_and_round_trips():
    pairs = LandmarkPairs.from_document(DOCUMENT)
    assert pairs.names == ("chin", "crown", "nose_tip")
    np.testing.assert_array_equal(pairs.source[2], [0.0, 1.6, 0.1])
    np.testing.assert_array_equal(pairs.target[1], [0.0, 0.0, 1800.0])
    again = LandmarkPairs.from_document(pairs.to_document())
    assert again.digest() == pairs.digest() and len(pairs.digest()) == 16
    moved = LandmarkPairs.from_document({**DOCUMENT, "target": {**DOCUMENT["target"], "chin": [0.0, -90.0, 1551.0]}})
    assert moved.digest() != pairs.digest()


def test_points_come_into_hairports_frame_from_each_files_units_and_axes():
    pairs = LandmarkPairs.from_document(DOCUMENT)
    # the target in millimetres with Z up and the face toward -Y; the source in centimetres, canonical axes
    canonical = pairs.in_canonical(InputFrame("m"), "cm", InputFrame("mm", "+z", "-y"))
    np.testing.assert_allclose(canonical.source, pairs.source * 0.01)
    # crown (0, 0, 1800) mm, Z up -> 1.8 m up; nose (0, -100, 1650) mm, front -Y -> 0.1 m toward +Z
    np.testing.assert_allclose(canonical.target[1], [0.0, 1.8, 0.0], atol=1e-12)
    np.testing.assert_allclose(canonical.target[2], [0.0, 1.65, 0.1], atol=1e-12)


@pytest.mark.parametrize("document, words", [
    ([1, 2], '"source" and "target"'),
    ({"source": DOCUMENT["source"]}, '"source" and "target"'),
    ({**DOCUMENT, "extra": {}}, '"source" and "target"'),
    ({"source": {}, "target": DOCUMENT["target"]}, "at least one point"),
    ({"source": DOCUMENT["source"], "target": {"crown": [0, 0, 1]}}, "'chin', 'nose_tip' named on the source only"),
    ({"source": {"crown": [0, 1.7, 0]}, "target": {"crown": [0, 0, 1], "ear": [1, 0, 1]}}, "'ear' named on the target"),
    ({"source": {"crown": [0, 1.7]}, "target": {"crown": [0, 0, 1]}}, "'crown' is not three finite numbers"),
    ({"source": {"crown": [0, float("nan"), 0]}, "target": {"crown": [0, 0, 1]}}, "not three finite numbers"),
    ({"source": {"crown": [0, "1.7", 0]}, "target": {"crown": [0, 0, 1]}}, "not three finite numbers"),
    ({"source": {"crown": [0, True, 0]}, "target": {"crown": [0, 0, 1]}}, "not three finite numbers"),
    ({"source": {"": [0, 1, 0]}, "target": {"": [0, 0, 1]}}, "1 to 64 characters"),
    ({side: {f"p{i}": [0, 0, i] for i in range(MAX_LANDMARKS + 1)} for side in ("source", "target")},
     f"{MAX_LANDMARKS + 1} landmarks, more than the limit of {MAX_LANDMARKS}"),
])
def test_malformed_documents_are_refused_by_name(document, words):
    with pytest.raises(InputError) as error:
        LandmarkPairs.from_document(document, "marks.json")
    assert error.value.code == "bad_landmarks" and error.value.source.startswith("marks.json") and words in str(error.value)


def test_files_too_large_or_not_json_are_refused(tmp_path):
    good = tmp_path / "marks.json"
    good.write_text(json.dumps(DOCUMENT))
    assert read_landmarks(good).names == ("chin", "crown", "nose_tip")
    for name, content, code in (("big.json", " " * (MAX_LANDMARKS_FILE_BYTES + 1), "too_large"),
                                ("torn.json", json.dumps(DOCUMENT)[:40], "bad_json"),
                                ("deep.json", "[" * 60_000, "too_deep")):
        path = tmp_path / name
        path.write_text(content)
        with pytest.raises(InputError) as error:
            read_landmarks(path)
        assert error.value.code == code and error.value.source == str(path)
