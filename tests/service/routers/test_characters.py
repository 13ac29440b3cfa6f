"""``/v1/characters``: uploads validated and content-addressed per key."""

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
