"""Uploads resolve nothing outside themselves, through the real app on the tests' Redis.

A penetration test uploaded a ``.usda`` whose ``subLayers`` named a groom on the server's disk: the
hairstyle held the server file's strands. Here the same upload (and a character stage referencing a server
body, a ``.gltf`` whose buffer names another upload's blob) is answered 422 ``external_reference`` and keeps
no blob, while the server file's strands uploaded as they are are accepted (so the 422 is the link's, not
the strands'). The worker reads a stored upload with the same default: a stored stage naming a file fails
its run with the same code.
"""

from __future__ import annotations

import json
import warnings

import pytest

from tests.integration.deployment import KEY, in_process_app, service_env
from tests.integration.test_hostile_inputs import _blobs, _referenced

AUTH = {"Authorization": f"Bearer {KEY}"}


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict:
    """A toy source character, and the server's own files outside the storage: a groom on that character
    (``secret.usda``, real strands) and a USD body."""
    from hairport.solver.io.hair import write_hair
    from hairport.solver.synthetic import toy
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import write_character
    from tests.solver.io.character.usd_samples import write_scene

    d = tmp_path_factory.mktemp("external-inputs")
    source = toy.toy_character(name="source")
    write_character(source, d / "source.obj", d / "source.skeleton.json")
    hair = generate_groom(source, "short", 40, 10, seed=0)
    write_hair(d / "secret.usda", hair)
    write_scene(d / "body.usdc", source, meters_per_unit=1.0)
    return {"dir": d, "hair": hair}


@pytest.fixture(scope="module")
def deployment(tmp_path_factory, redis_url):
    storage = tmp_path_factory.mktemp("external-storage")
    with in_process_app(service_env(storage, redis_url)) as (settings, _, client):
        yield {"client": client, "storage": storage, "settings": settings}


def test_uploads_naming_server_files_are_refused_and_keep_no_blob(deployment, files):
    client, storage, d = deployment["client"], deployment["storage"], files["dir"]
    character = client.post("/v1/characters", headers=AUTH, files={
        "mesh": ("source.obj", (d / "source.obj").read_bytes()),
        "skeleton": ("source.json", (d / "source.skeleton.json").read_bytes())})
    assert character.status_code == 201, character.text
    source_id = character.json()["id"]
    secret = str(d / "secret.usda")
    sublayered = f"#usda 1.0\n(\n    metersPerUnit = 1\n    subLayers = [@{secret}@]\n)\n".encode()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        refused = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": source_id},
                              files={"hair": ("groom.usda", sublayered)})
        accepted = client.post("/v1/hairstyles", headers=AUTH, data={"source_character_id": source_id},
                               files={"hair": ("groom.usda", (d / "secret.usda").read_bytes())})
    assert (refused.status_code, refused.json()["code"]) == (422, "external_reference"), refused.text
    assert refused.json()["detail"].startswith("hair: names a file outside itself") and "sublayer '" in \
        refused.json()["detail"]
    # the server file's strands themselves are a valid groom of this character
    assert accepted.status_code == 201 and accepted.json()["strands"] == files["hair"].n_strands, accepted.text
    body = str(d / "body.usdc")
    referencing = (f'#usda 1.0\n(\n    metersPerUnit = 1\n)\n\ndef Xform "World" (\n'
                   f'    prepend references = @{body}@\n)\n{{\n}}\n').encode()
    stored_obj = next(path for path in (storage / "blobs").rglob("*.obj"))
    gltf = {"asset": {"version": "2.0"}, "buffers": [{"uri": f"../{stored_obj.parent.name}/{stored_obj.name}",
                                                      "byteLength": 12}]}
    for name, data in (("body.usda", referencing), ("body.gltf", json.dumps(gltf).encode())):
        response = client.post("/v1/characters", headers=AUTH, files={"mesh": (name, data)})
        assert (response.status_code, response.json()["code"]) == (422, "external_reference"), (name, response.text)
    assert _blobs(storage) - _referenced(storage) == set(), "a refused upload kept its blob"


def test_the_worker_refuses_a_stored_stage_naming_a_server_file(deployment, files):
    from hairport import solver
    from hairport.records import BlobRef, HairstyleRecord
    from hairport.worker import loading

    client, d = deployment["client"], files["dir"]
    repository = client.app.state.repository
    stored = next(record for record in (repository.get(HairstyleRecord, path.stem) for path in
                                        (deployment["storage"] / "records").rglob("*.json")) if record is not None)
    # a stage stored before uploads were checked for links (or by any other way in): the worker reads it safely too
    blob = repository.storage.save_bytes(f"#usda 1.0\n(\n    metersPerUnit = 1\n    subLayers = [@{d / 'secret.usda'}@]"
                                         "\n)\n".encode(), ".usda")
    linked = stored.model_copy(update={"hair": BlobRef(sha256=blob.sha256, suffix=".usda", size=blob.size)})
    with pytest.raises(solver.InputError) as caught:
        loading.read_source(repository, deployment["settings"], linked)
    info = loading.error_info(caught.value, 10)
    assert info.code == "external_reference" and "sublayer" in info.message
    assert loading.read_source(repository, deployment["settings"], stored).hair.n_strands == files["hair"].n_strands
