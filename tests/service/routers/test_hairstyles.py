"""``/v1/hairstyles``: validated uploads, one record per content, preprocessing sent once (no worker here)."""

import struct

import numpy as np
import pytest

from hairport.worker.app import PREPROCESS_QUEUE

from ..conftest import AUTH
from .uploads import upload_character, write_inputs


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    return write_inputs(tmp_path_factory.mktemp("hairstyles"))


def waiting(client, queue: str) -> int:
    celery = client.app.state.queue.celery
    with celery.connection_for_read() as connection:
        return connection.SimpleQueue(client.app.state.queue.names[queue]).qsize()


def test_one_record_and_one_preprocessing_per_content(client, files):
    source = upload_character(client, files, "source")
    form = {"source_character_id": source, "guides": "5"}
    first = client.post("/v1/hairstyles", headers=AUTH, data=form, files={"hair": ("g.data", files["groom.data"])})
    second = client.post("/v1/hairstyles", headers=AUTH, data=form, files={"hair": ("h.data", files["groom.data"])})
    assert first.status_code == second.status_code == 201 and first.json()["id"] == second.json()["id"]
    body = first.json()
    assert (body["strands"], body["particles"], body["format"]) == (20, 120, "data")
    assert body["options"] == {"k": 5, "guides": 5, "anchoring": "auto", "guides_from": None} and body["preprocessing"] == {"state": "queued", "error": None}
    assert waiting(client, PREPROCESS_QUEUE) == 1
    assert client.get(f"/v1/hairstyles/{body['id']}", headers=AUTH).json() == body
    other = client.post("/v1/hairstyles", headers=AUTH, data={**form, "guides": "6"},
                        files={"hair": ("g.data", files["groom.data"])})
    assert other.json()["id"] != body["id"] and waiting(client, PREPROCESS_QUEUE) == 2


@pytest.mark.parametrize("form, name, status, code", [
    ({"units": "ft"}, "g.data", 422, "bad_units"),
    ({"k": "0"}, "g.data", 422, "bad_option"),
    ({}, "g.fbx", 415, "unknown_format"),
])
def test_bad_uploads(client, files, form, name, status, code):
    source = upload_character(client, files, "source")
    response = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": source, **form},
                           files={"hair": (name, files["groom.data"])})
    assert (response.status_code, response.json()["code"]) == (status, code)


def test_a_character_without_a_skeleton_is_anchored_by_its_surface_unless_bones_are_asked_for(client, files):
    bare = client.post("/v1/characters", headers=AUTH, files={"mesh": ("b.obj", files["source.obj"])}).json()["id"]
    response = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": bare, "anchoring": "bones"},
                           files={"hair": ("g.data", files["groom.data"])})
    assert (response.status_code, response.json()["code"]) == (422, "no_skeleton")
    assert "anchor by the surface" in response.json()["detail"]
    response = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": bare},
                           files={"hair": ("g.data", files["groom.data"])})
    assert response.status_code == 201 and response.json()["options"]["anchoring"] == "auto"
    response = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": bare, "anchoring": "ribs"},
                           files={"hair": ("g.data", files["groom.data"])})
    assert response.status_code == 422


#: hair files with nothing to retarget, each refused at upload: (name, bytes, code, words of the detail)
WITHOUT_HAIR = [
    ("zero.data", struct.pack("<i", 0), "empty_hair", "no strand of two or more points"),
    ("dots.data", struct.pack("<ii3fi3f", 2, 1, 0, 1.6, 0, 1, 0.1, 1.6, 0), "empty_hair", "no strand of two"),
    ("flat.data", struct.pack("<ii6f", 1, 2, *([0.0, 1.6, 0.0] * 2)), "empty_hair", "every strand (1) has zero length"),
    ("empty.obj", b"", "empty_hair", "no polyline ('l') records"),
    ("garbage.obj", np.random.default_rng(7).integers(1, 256, 4096, dtype=np.uint8).tobytes(), "not_text",
     "is not an OBJ record"),
]


@pytest.mark.parametrize("name, data, code, words", WITHOUT_HAIR, ids=[case[0] for case in WITHOUT_HAIR])
def test_hair_files_without_hair_are_422_at_upload(client, files, name, data, code, words):
    source = upload_character(client, files, "source")
    response = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": source},
                           files={"hair": (name, data)})
    body = response.json()
    assert (response.status_code, body["code"]) == (422, code), body
    assert body["detail"].startswith("hair: ") and words in body["detail"]
    assert waiting(client, PREPROCESS_QUEUE) == 0  # nothing for a worker to preprocess


def test_units_are_inferred_and_a_groom_in_other_units_is_refused_at_upload(client, files, tmp_path):
    import numpy as np

    from hairport.solver import read_hair

    source = upload_character(client, files, "source")
    (tmp_path / "g.data").write_bytes(files["groom.data"])
    hair = read_hair(tmp_path / "g.data")
    inferred = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": source},
                           files={"hair": ("g.data", files["groom.data"])})
    assert inferred.status_code == 201 and inferred.json()["units"] == "auto"
    in_mm = tmp_path / "mm.npz"
    np.savez(in_mm, format=np.array("hairport-hair"), version=np.array(1), points=hair.points * 1000,
             offsets=hair.offsets)
    # the body states meters (its sidecar): a groom in millimetres is read as such
    fitted = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": source},
                         files={"hair": ("mm.npz", in_mm.read_bytes())})
    assert fitted.status_code == 201, fitted.text
    refused = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": source, "units": "m"},
                          files={"hair": ("mm.npz", in_mm.read_bytes())})
    assert (refused.status_code, refused.json()["code"]) == (422, "units_mismatch")
    assert refused.json()["detail"].startswith("hair: ") and "units=mm" in refused.json()["detail"]
    assert waiting(client, PREPROCESS_QUEUE) == 2  # the refused one sent nothing


def test_the_caller_lists_its_own_hairstyles_with_their_preprocessing(client, files):
    source = upload_character(client, files, "source")
    ids = [client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": source, "guides": guides},
                       files={"hair": ("g.data", files["groom.data"])}).json()["id"] for guides in ("4", "5")]
    page = client.get("/v1/hairstyles", headers=AUTH).json()
    assert [item["id"] for item in page["hairstyles"]] == ids[::-1] and page["total"] == 2
    assert {item["preprocessing"]["state"] for item in page["hairstyles"]} == {"queued"}
    assert client.get("/v1/hairstyles", headers={"X-API-Key": "other"}).status_code == 401
    assert client.get("/v1/hairstyles", headers=AUTH, params={"offset": -1}).status_code == 422


def test_a_listing_reads_the_records_of_its_page_whatever_other_owners_keep(client, monkeypatch):
    from hairport.records import BlobRef, HairstyleRecord, PreprocessSettings
    from hairport.service.auth import owner_of

    from ..conftest import KEY

    repository = client.app.state.repository
    for number in range(150):
        owner = owner_of(KEY) if number % 50 == 0 else f"kother{number % 3}"
        repository.put(HairstyleRecord(id=f"{number:032x}", owner=owner, created_at=float(number),
                                       source_character_id="c" * 32, hair=BlobRef(sha256="b" * 64, suffix=".data"),
                                       format="data", units="m", options=PreprocessSettings(k=5, guides=20),
                                       artifact_key=f"{number:064x}", strands=2, particles=4), f"{number:032x}")
    reads = []
    original = repository.storage.get_record_text
    monkeypatch.setattr(repository.storage, "get_record_text",
                        lambda kind, rid: reads.append((kind, rid)) or original(kind, rid))
    page = client.get("/v1/hairstyles", headers=AUTH, params={"limit": 2}).json()
    assert [item["id"] for item in page["hairstyles"]] == [f"{100:032x}", f"{50:032x}"] and page["total"] == 3
    # each item: its record and its preprocessing's (shared by every hairstyle of the same inputs)
    assert reads == [("hairstyles", f"{100:032x}"), ("hairstyles", f"{50:032x}"),
                     ("preprocessing", f"{100:064x}"), ("preprocessing", f"{50:064x}")]
