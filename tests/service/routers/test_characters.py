"""``/v1/characters``: uploads validated and content-addressed per key."""

import numpy as np
import pytest

from hairport.solver.synthetic import toy
from hairport.solver.synthetic.makehuman import write_character

from ..conftest import AUTH


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("characters")
    write_character(toy.toy_character(name="toy"), folder / "toy.obj", folder / "toy.skeleton.json")
    return {"mesh": (folder / "toy.obj").read_bytes(), "skeleton": (folder / "toy.skeleton.json").read_bytes()}


def test_upload_twice_gives_one_character(client, files):
    upload = {"mesh": ("toy.obj", files["mesh"]), "skeleton": ("toy.skeleton.json", files["skeleton"])}
    first = client.post("/v1/characters", headers=AUTH, files=upload)
    second = client.post("/v1/characters", headers=AUTH, files=upload)
    assert first.status_code == second.status_code == 201 and first.json() == second.json()
    body = first.json()
    assert body["vertices"] == 3842 and body["has_skeleton"] and "head" in body["bones"]
    assert client.get(f"/v1/characters/{body['id']}", headers=AUTH).json() == body
    without_skeleton = client.post("/v1/characters", headers=AUTH, files={"mesh": ("toy.obj", files["mesh"])},
                                   data={"units": "m"})
    assert without_skeleton.status_code == 201 and without_skeleton.json()["id"] != body["id"]
    assert without_skeleton.json()["bones"] == [] and without_skeleton.json()["units"] == "m"


def test_bad_uploads(client, files):
    assert client.post("/v1/characters", headers=AUTH, files={"mesh": ("toy.stl", files["mesh"])}).json()["code"] == \
        "unknown_format"
    assert client.post("/v1/characters", headers=AUTH, files={"mesh": ("toy.obj", files["mesh"])},
                       data={"units": "ft"}).json()["code"] == "bad_units"
    cut = client.post("/v1/characters", headers=AUTH, files={"mesh": ("toy.obj", files["mesh"][:5000])})
    assert cut.status_code == 422 and cut.json()["detail"].startswith("mesh: ")
    assert client.get("/v1/characters/" + "0" * 32, headers=AUTH).status_code == 404


@pytest.mark.parametrize("mesh, code, words", [
    (b"v 0 0 0\nv 1 0 0\nv 0 1 0\n", "empty_mesh", "0 faces"),
    (b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", "empty_mesh", "every face (1) has zero area"),
    (b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n\0\x01\x02", "not_text", "NUL byte"),
], ids=["no-faces", "zero-area", "binary"])
def test_meshes_without_faces_are_422_at_upload(client, mesh, code, words):
    response = client.post("/v1/characters", headers=AUTH, files={"mesh": ("body.obj", mesh)})
    body = response.json()
    assert (response.status_code, body["code"]) == (422, code) and body["detail"].startswith("mesh: ")
    assert words in body["detail"]


def test_units_and_axes_are_stated_given_or_left_to_inference(client, files):
    upload = {"mesh": ("toy.obj", files["mesh"]), "skeleton": ("toy.skeleton.json", files["skeleton"])}
    rigged = client.post("/v1/characters", headers=AUTH, files=upload).json()
    assert (rigged["units"], rigged["up_axis"], rigged["front_axis"]) == ("m", "auto", "auto")  # the sidecar's
    bare = client.post("/v1/characters", headers=AUTH, files={"mesh": ("toy.obj", files["mesh"])}).json()
    assert (bare["units"], bare["up_axis"]) == ("auto", "auto")  # an OBJ alone states nothing
    turned = client.post("/v1/characters", headers=AUTH, files=upload, data={"up_axis": "z", "front_axis": "-Y"})
    assert turned.status_code == 201, turned.text
    assert (turned.json()["up_axis"], turned.json()["front_axis"]) == ("+z", "-y")
    assert turned.json()["id"] != rigged["id"]  # another frame, another character
    auto = client.post("/v1/characters", headers=AUTH, files=upload, data={"units": "auto", "up_axis": "auto"})
    assert auto.json()["id"] == rigged["id"]
    for form, words in (({"up_axis": "up"}, "up_axis must be one of auto"),
                        ({"up_axis": "z", "front_axis": "-z"}, "perpendicular")):
        refused = client.post("/v1/characters", headers=AUTH, files=upload, data=form)
        assert (refused.status_code, refused.json()["code"]) == (422, "bad_axis") and words in refused.json()["detail"]


def test_the_caller_lists_its_own_characters_newest_first(client, files):
    ids = [client.post("/v1/characters", headers=AUTH, files={"mesh": ("toy.obj", files["mesh"])},
                       data={"units": units}).json()["id"] for units in ("m", "cm", "mm")]
    page = client.get("/v1/characters", headers=AUTH, params={"limit": 2}).json()
    assert [item["id"] for item in page["characters"]] == ids[::-1][:2] and page["total"] == 3
    assert page["next_offset"] == 2 and page["characters"][0]["units"] == "mm"
    assert client.get("/v1/characters", headers={"X-API-Key": "nobody"}).status_code == 401
    assert client.get("/v1/characters", headers=AUTH, params={"limit": 0}).status_code == 422


def test_a_character_mesh_is_drawn_in_its_own_axes_up_its_given_axis_or_its_longest_extent(client, files):
    from hairport.solver import display

    character = client.post("/v1/characters", headers=AUTH, files={"mesh": ("toy.obj", files["mesh"])},
                            data={"units": "m"}).json()
    header, upright = display.decode(client.get(f"/v1/characters/{character['id']}/mesh", headers=AUTH).content)
    assert upright["vertices"].shape == (3842, 3) and upright["faces"].shape == (character["faces"], 3)
    assert header["up"] == [0.0, 1.0, 0.0] and header["up_found"] == "longest extent" and header["units"] == "m"
    # the same body Z up in millimetres, its up axis given
    body = toy.toy_character(name="toy")
    z_up = body.vertices[:, [0, 2, 1]] * [1000.0, -1000.0, 1000.0]
    text = "".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in z_up)
    text += "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in body.faces)
    rotated = client.post("/v1/characters", headers=AUTH, files={"mesh": ("z.obj", text.encode())},
                          data={"up_axis": "z", "units": "mm"}).json()
    header, lying = display.decode(client.get(f"/v1/characters/{rotated['id']}/mesh", headers=AUTH).content)
    assert header["up"] == [0.0, 0.0, 1.0] and header["up_found"] == "given" and header["units"] == "mm"
    np.testing.assert_allclose(np.ptp(lying["vertices"], axis=0)[[0, 2, 1]], np.ptp(upright["vertices"], axis=0),
                               rtol=1e-5)
    assert client.get("/v1/characters/" + "0" * 32 + "/mesh", headers=AUTH).status_code == 404


def test_a_listing_reads_the_records_of_its_page_whatever_other_owners_keep(client, monkeypatch):
    from hairport.records import BlobRef, CharacterRecord
    from hairport.service.auth import owner_of

    from ..conftest import KEY

    repository = client.app.state.repository
    for number in range(150):
        owner = owner_of(KEY) if number % 50 == 0 else f"kother{number % 3}"
        repository.put(CharacterRecord(id=f"{number:032x}", owner=owner, created_at=float(number), vertices=3, faces=1,
                                       mesh=BlobRef(sha256=f"{number:064x}", suffix=".obj"), bones=[]),
                       f"{number:032x}")
    reads = []
    original = repository.storage.get_record_text
    monkeypatch.setattr(repository.storage, "get_record_text",
                        lambda kind, rid: reads.append(rid) or original(kind, rid))
    page = client.get("/v1/characters", headers=AUTH, params={"limit": 2}).json()
    assert [item["id"] for item in page["characters"]] == [f"{100:032x}", f"{50:032x}"] and page["total"] == 3
    assert reads == [f"{100:032x}", f"{50:032x}"]
