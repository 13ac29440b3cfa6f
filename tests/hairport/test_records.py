"""Typed records: states, ids, the artifact key, and the JSON round trip."""

import pytest

from hairport.records import (
    JOB_STATES,
    TERMINAL_STATES,
    WAITING_STATES,
    BatchTotals,
    BlobRef,
    CharacterRecord,
    JobRecord,
    PreprocessSettings,
    artifact_key,
    digest,
    new_job_id,
    owned_id,
    progress_units,
)


def character(**changes) -> CharacterRecord:
    fields = dict(id="c" * 32, owner="kabc", created_at=1.0, mesh=BlobRef(sha256="a" * 64, suffix=".obj"),
                  skeleton=BlobRef(sha256="b" * 64, suffix=".json"), units="cm", vertices=8, faces=12, bones=["head"])
    return CharacterRecord(**{**fields, **changes})


def test_states():
    assert JOB_STATES == ("queued", "running", "stale", "succeeded", "failed", "cancelled")
    assert TERMINAL_STATES == ("succeeded", "failed", "cancelled")
    assert WAITING_STATES == ("queued", "stale")


def test_digest_is_stable_and_key_order_free():
    assert digest({"a": 1, "b": [1, 2]}) == digest({"b": [1, 2], "a": 1})
    assert digest("x") != digest("y") and len(digest("x")) == 64
    # the JSON of the parts, compact, sorted keys
    import hashlib

    assert digest("x", 1) == hashlib.sha256(b'["x",1]').hexdigest()


def test_ids_are_scoped_to_their_owner():
    mine, theirs = owned_id("k1", "content"), owned_id("k2", "content")
    assert mine != theirs and len(mine) == 32 and set(mine) <= set("0123456789abcdef")
    assert owned_id("k1", "content") == mine
    assert len({new_job_id() for _ in range(100)}) == 100


def test_artifact_key_changes_with_every_input():
    options = PreprocessSettings(k=5, guides=300)
    base = artifact_key(character(), "h" * 64, "m", options, 1)
    assert base == artifact_key(character(), "h" * 64, "m", PreprocessSettings(k=5, guides=300), 1)
    changed = [
        artifact_key(character(mesh=BlobRef(sha256="d" * 64, suffix=".obj")), "h" * 64, "m", options, 1),
        artifact_key(character(skeleton=None), "h" * 64, "m", options, 1),
        artifact_key(character(units="m"), "h" * 64, "m", options, 1),
        artifact_key(character(), "e" * 64, "m", options, 1),
        artifact_key(character(), "h" * 64, "mm", options, 1),
        artifact_key(character(), "h" * 64, "m", PreprocessSettings(k=6, guides=300), 1),
        artifact_key(character(), "h" * 64, "m", options, 2),
    ]
    assert len({base, *changed}) == 8


def test_job_record_round_trips_and_ignores_unknown_fields():
    job = JobRecord(id="j" * 32, owner="kabc", hairstyle_id="h" * 32, target_character_id="c" * 32,
                    options={"method": "multiscale"}, preprocess_options=PreprocessSettings(k=5, guides=20),
                    artifact_key="a" * 64, output_format="ply", created_at=2.0, updated_at=2.0)
    document = job.model_dump(mode="json")
    assert document["state"] == "queued" and document["stage"] == "queued" and document["attempts"] == 0
    assert JobRecord.model_validate({**document, "from_a_newer_version": 1}) == job
    with pytest.raises(ValueError):
        JobRecord.model_validate({**document, "state": "paused"})


def test_artifact_key_changes_with_a_characters_given_axes():
    options = PreprocessSettings(k=5, guides=300)
    base = artifact_key(character(), "h" * 64, "auto", options, 1)
    turned = artifact_key(character(up_axis="+z", front_axis="-y"), "h" * 64, "auto", options, 1)
    other = artifact_key(character(up_axis="+z"), "h" * 64, "auto", options, 1)
    assert len({base, turned, other}) == 3
    # axes left to inference keep the key of a record that never had them
    assert artifact_key(character(up_axis=None), "h" * 64, "auto", options, 1) == base


def test_a_batch_shows_complete_only_when_every_job_has_ended():
    # one job succeeded, the other at progress 1 but still writing its outputs
    running = BatchTotals(counts={**dict.fromkeys(JOB_STATES, 0), "succeeded": 1, "running": 1},
                          progress_units=progress_units(1.0))
    assert running.state == "running" and running.progress == 0.9999
    nearly = BatchTotals(counts={**dict.fromkeys(JOB_STATES, 0), "succeeded": 1, "running": 1},
                         progress_units=progress_units(0.5))
    assert nearly.progress == 0.75
    done = BatchTotals(counts={**dict.fromkeys(JOB_STATES, 0), "succeeded": 1, "failed": 1})
    assert done.state == "done" and done.progress == 1.0
