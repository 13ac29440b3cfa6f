"""A toy character and a groom uploaded through the API (shared by the router tests)."""

from hairport.solver import write_hair
from hairport.solver.synthetic import toy
from hairport.solver.synthetic.groom import generate_groom
from hairport.solver.synthetic.makehuman import write_character

from ..conftest import AUTH


def write_inputs(folder) -> dict:
    """OBJ + skeleton sidecar of two toy characters and a 20-strand groom on the first, as bytes."""
    source, target = toy.toy_character(name="source"), toy.toy_character(neck_length=0.15, name="target")
    for name, character in (("source", source), ("target", target)):
        write_character(character, folder / f"{name}.obj", folder / f"{name}.skeleton.json")
    write_hair(folder / "groom.data", generate_groom(source, "short", 20, 6, seed=0))
    return {name: (folder / name).read_bytes() for name in ("source.obj", "source.skeleton.json", "target.obj",
                                                            "target.skeleton.json", "groom.data")}


def upload_character(client, files, name: str) -> str:
    response = client.post("/v1/characters", headers=AUTH, files={
        "mesh": (f"{name}.obj", files[f"{name}.obj"]), "skeleton": (f"{name}.skeleton.json",
                                                                    files[f"{name}.skeleton.json"])})
    assert response.status_code == 201, response.text
    return response.json()["id"]
