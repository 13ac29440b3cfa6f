"""Files that name other files (solver/io/external.py): by default a read opens nothing outside the file it is
given. USD stages naming a file on the server by any arc (hair and characters, text, crate, packages) are
refused with ``external_reference`` and the named file is never opened; with ``allow_external_files`` (the
command line) the same stages compose it, which is the hole the default closes. OBJ ``mtllib`` and a PLY's
texture are never opened, allowed or not."""

from __future__ import annotations

import sys
from contextlib import contextmanager

import numpy as np
import pytest
from pxr import Sdf

from hairport.solver.io.character.load import read_character
from hairport.solver.io.external import EXTERNAL_REFERENCE, MAX_QUOTED_CHARS, external_reference, quoted
from hairport.solver.io.hair import ReadLimits, read_hair, read_hair_bytes, recorded_units, write_hair
from hairport.solver.io.hair.common import ReadContext
from hairport.solver.io.usd.stage import open_stage
from hairport.solver.model.errors import InputError
from hairport.solver.model.hair import Hair
from hairport.solver.synthetic import toy
from tests.solver.io.character.usd_samples import write_scene
from tests.solver.io.hair.samples import helix_hair

#: integration, not unit: every stage is read in a sandboxed child process
pytestmark = pytest.mark.integration

#: the server's groom sits here (meters): a coordinate no upload of these tests holds
SECRET_SHIFT = 4.25
ALLOWED = ReadLimits(allow_external_files=True)
HEADER = "#usda 1.0\n(\n    metersPerUnit = 1\nSUBLAYERS)\n\n"
#: uploads naming the server's groom (SECRET: its absolute path) by every arc that composes it, and the
#: kind of link the refusal names
COMPOSING = {
    "sublayer absolute": ("    subLayers = [@SECRET@]\n", "", "sublayer"),
    "sublayer relative": ("    subLayers = [@./secret.usda@]\n", "", "sublayer"),
    "reference": ("", 'def Xform "Groom" (\n    prepend references = @SECRET@</Groom>\n)\n{\n}\n', "reference"),
    "payload": ("", 'def Xform "Groom" (\n    prepend payload = @SECRET@</Groom>\n)\n{\n}\n', "payload"),
    "inherits": ("", 'class "_hair" (\n    prepend references = @SECRET@</Groom>\n)\n{\n}\n\n'
                     'def Xform "Groom" (\n    inherits = </_hair>\n)\n{\n}\n', "reference"),
    "specializes": ("", 'class "_hair" (\n    prepend payload = @SECRET@</Groom>\n)\n{\n}\n\n'
                        'def Xform "Groom" (\n    specializes = </_hair>\n)\n{\n}\n', "payload"),
    "variant": ("", 'def Xform "Groom" (\n    variants = {\n        string look = "long"\n    }\n'
                    '    prepend variantSets = "look"\n)\n{\n    variantSet "look" = {\n'
                    '        "long" (\n            prepend references = @SECRET@</Groom>\n        ) {\n'
                    '        }\n    }\n}\n', "reference"),
}
#: links that compose nothing the reader reads, refused all the same: (body, kind, the name in the message)
NOT_COMPOSING = {
    "value clips": ('def Xform "Clipped" (\n    clips = {\n        dictionary default = {\n'
                    '            double2[] active = [(0, 0)]\n            asset[] assetPaths = [@SECRET@]\n'
                    '            string primPath = "/Clipped"\n        }\n    }\n)\n{\n}\n', "value clip", "SECRET"),
    "clip template": ('def Xform "Clipped" (\n    clips = {\n        dictionary default = {\n'
                      '            string templateAssetPath = "SECRET.###.usda"\n'
                      '            double templateStartTime = 0\n        }\n    }\n)\n{\n}\n', "value clip",
                      "SECRET.###.usda"),
    "asset attribute": ('def Scope "Material"\n{\n    asset file = @/etc/passwd@\n}\n', "asset-valued attribute",
                        "/etc/passwd"),
}


@pytest.fixture(scope="module")
def server(tmp_path_factory) -> dict:
    """A folder of the server holding a real groom (``secret.usda``) and a real character (``body.usdc``)."""
    folder = tmp_path_factory.mktemp("server")
    base = helix_hair(6, seed=3)
    secret = Hair(base.points + SECRET_SHIFT, base.offsets)
    write_hair(folder / "secret.usda", secret)
    body = toy.toy_character(name="secret")
    write_scene(folder / "body.usdc", body, meters_per_unit=1.0)
    return {"folder": folder, "hair": secret, "body": body, "path": str(folder / "secret.usda")}


def upload_text(server: dict, sublayers: str, body: str) -> str:
    return (HEADER.replace("SUBLAYERS", sublayers) + body).replace("SECRET", server["path"])


def refusal(call, *args, **kwargs) -> InputError:
    with pytest.raises(InputError) as caught:
        call(*args, **kwargs)
    assert caught.value.code == EXTERNAL_REFERENCE, caught.value
    return caught.value


@pytest.mark.parametrize("case", sorted(COMPOSING))
def test_a_stage_composing_a_server_file_is_refused_and_reads_it_only_when_allowed(server, case):
    sublayers, body, kind = COMPOSING[case]
    text = upload_text(server, sublayers, body)
    upload = server["folder"] / f"upload-{case.replace(' ', '-')}.usda"
    upload.write_text(text)  # beside the secret: a relative name would find it
    named = "./secret.usda" if "relative" in case else server["path"]
    # an upload's bytes, and the stored file the worker reads, are refused naming the link
    for error in (refusal(read_hair_bytes, text.encode(), "usda", source="upload.usda"), refusal(read_hair, upload)):
        assert f"{kind} {quoted(named)}" in error.problem and str(SECRET_SHIFT) not in str(error)
    # in this process: refused on the root layer alone, the server's file never opened
    ctx = ReadContext("upload.usda", ReadLimits(), "m")
    refusal(open_stage, str(upload), ctx)
    assert Sdf.Layer.Find(server["path"]) is None
    # the command line's read composes the server's strands: what the refusal keeps from an upload
    composed = read_hair(upload, limits=ALLOWED)
    np.testing.assert_allclose(composed.points, server["hair"].points, atol=1e-6)


@pytest.mark.parametrize("case", sorted(NOT_COMPOSING))
def test_clips_and_asset_paths_are_refused_too(server, case, tmp_path):
    body, kind, name = NOT_COMPOSING[case]
    own = tmp_path / "own.usda"
    write_hair(own, helix_hair(3))
    text = own.read_text() + "\n" + body.replace("SECRET", server["path"])
    error = refusal(read_hair_bytes, text.encode(), "usda", source="upload.usda")
    assert f"{kind} {quoted(name.replace('SECRET', server['path']))}" in error.problem
    (tmp_path / "upload.usda").write_text(text)
    assert read_hair(tmp_path / "upload.usda", limits=ALLOWED).n_strands == 3  # its own strands, nothing else


def test_a_crate_upload_with_a_sublayer_is_refused(server, tmp_path):
    layer = Sdf.Layer.CreateAnonymous(".usda")
    layer.ImportFromString(upload_text(server, "    subLayers = [@SECRET@]\n", ""))
    layer.Export(str(tmp_path / "upload.usdc"))
    data = (tmp_path / "upload.usdc").read_bytes()
    assert data.startswith(b"PXR-USDC")
    for fmt in ("usdc", "usd"):
        error = refusal(read_hair_bytes, data, fmt, source=f"upload.{fmt}")
        assert f"sublayer {quoted(server['path'])}" in error.problem
    assert read_hair(tmp_path / "upload.usdc", limits=ALLOWED).n_strands == server["hair"].n_strands


def test_packages_are_not_read_whatever_they_hold(server, tmp_path):
    # decided: no .usdz is read, not even one whose references stay inside it; its bytes under a USD
    # extension are not a stage
    (tmp_path / "inside.usda").write_text(upload_text(server, "    subLayers = [@other.usda@]\n", ""))
    (tmp_path / "other.usda").write_text(server["folder"].joinpath("secret.usda").read_text())
    writer = Sdf.ZipFileWriter.CreateNew(str(tmp_path / "groom.usdz"))
    for name in ("inside.usda", "other.usda"):
        writer.AddFile(str(tmp_path / name), name)
    writer.Save()
    package = (tmp_path / "groom.usdz").read_bytes()
    for source, fmt, code in (("groom.usdz", None, "unknown_format"), ("groom.usd", "usd", "bad_header"),
                              ("groom.usda", "usda", "bad_header")):
        with pytest.raises(InputError) as caught:
            read_hair_bytes(package, fmt, source=source)
        assert caught.value.code == code
    for name, code in (("body.usdz", "unknown_format"), ("body.usd", "bad_header")):
        (tmp_path / name).write_bytes(package)
        with pytest.raises(InputError) as caught:
            read_character(tmp_path / name)
        assert caught.value.code == code


def test_a_character_stage_naming_the_server_character_is_refused(server, tmp_path):
    body_path = str(server["folder"] / "body.usdc")
    for name, text in (("sublayer", f"#usda 1.0\n(\n    metersPerUnit = 1\n    subLayers = [@{body_path}@]\n)\n"),
                       ("reference", f'#usda 1.0\n(\n    metersPerUnit = 1\n)\n\ndef Xform "World" (\n'
                                     f'    prepend references = @{body_path}@\n)\n{{\n}}\n')):
        upload = tmp_path / f"{name}.usda"
        upload.write_text(text)
        error = refusal(read_character, upload)
        assert f"{name} {quoted(body_path)}" in error.problem
        character, units = read_character(upload, allow_external_files=True)
        assert (character.n_vertices, units) == (server["body"].n_vertices, "m")


def test_the_recorded_units_come_from_the_root_layer_alone(server, tmp_path):
    upload = tmp_path / "upload.usda"
    upload.write_text(upload_text(server, "    subLayers = [@SECRET@]\n", "").replace("= 1\n", "= 0.001\n"))
    assert recorded_units(upload) == "mm"  # the sublayer says 1 (m): not opened, not used


def test_a_stage_composed_in_this_process_would_show_in_the_registry(server, tmp_path):
    # the proof the refusals above rely on can fail: composing opens the named layer here
    upload = tmp_path / "upload.usda"
    upload.write_text(upload_text(server, "    subLayers = [@SECRET@]\n", ""))
    stage = open_stage(str(upload), ReadContext("upload.usda", ALLOWED, "m"), allow_external_files=True)
    assert Sdf.Layer.Find(server["path"]) is not None
    del stage


def test_names_in_messages_are_one_bounded_printable_line():
    name = "/srv/" + "\x00\n\u202e" * 3 + "x" * 500
    text = quoted(name)
    assert len(text) == MAX_QUOTED_CHARS + 2 and text.isprintable() and text.endswith("\u2026'")
    error = external_reference("sublayer", name, "upload.usda", where="/" + "y" * 400, more=3)
    assert error.code == EXTERNAL_REFERENCE and len(error.problem) < 300 and error.problem.isprintable()
    assert "(and 3 more)" in error.problem


def test_a_long_asset_path_in_a_stage_gives_a_bounded_message(server):
    long_name = "/srv/" + "d" * 1000 + "/groom.usda"
    error = refusal(read_hair_bytes, f"#usda 1.0\n(\n    subLayers = [@{long_name}@, @/b@]\n)\n".encode(), "usda",
                    source="upload.usda")
    assert len(error.problem) < 300 and "(and 1 more)" in error.problem


# ---------------------------------------------------------------- formats whose names are never followed

_OPENED: list[str] | None = None
_HOOKED = []


def _record(event: str, args: tuple) -> None:
    if event == "open" and _OPENED is not None:
        _OPENED.append(str(args[0]))


@contextmanager
def opened_files():
    """The paths this process opens inside the block (Python's ``open`` audit events)."""
    global _OPENED
    if not _HOOKED:  # an audit hook cannot be removed: one for the session, idle outside the block
        sys.addaudithook(_record)
        _HOOKED.append(True)
    _OPENED = []
    try:
        yield _OPENED
    finally:
        _OPENED = None


def test_obj_material_libraries_are_never_opened(tmp_path):
    (tmp_path / "body.mtl").write_text("newmtl skin\nKd 1 0 0\n")
    mtl = str(tmp_path / "body.mtl")
    (tmp_path / "body.obj").write_text(f"mtllib body.mtl\nmtllib {mtl}\nusemtl skin\n"
                                       "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "hair.obj").write_text(f"mtllib {mtl}\nv 0 0 0\nv 0 0.1 0\nv 0 0.2 0\nl 1 2 3\n")
    with opened_files() as opened:
        character, _ = read_character(tmp_path / "body.obj", allow_external_files=True)
        hair = read_hair(tmp_path / "hair.obj", limits=ALLOWED)
    assert (character.n_vertices, hair.n_particles) == (3, 3)
    assert str(tmp_path / "body.obj") in opened and mtl not in opened


def test_a_ply_texture_is_never_opened(tmp_path):
    (tmp_path / "skin.png").write_bytes(b"\x89PNG\r\n\x1a\n")
    header = ("ply\nformat ascii 1.0\ncomment TextureFile skin.png\nelement vertex 3\nproperty float x\n"
              "property float y\nproperty float z\n")
    (tmp_path / "body.ply").write_text(header + "element face 1\nproperty list uchar int vertex_indices\n"
                                       "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    (tmp_path / "hair.ply").write_text(header + "element strand 1\nproperty int nsegs\nend_header\n"
                                       "0 0 0\n0 0.1 0\n0 0.2 0\n2\n")
    with opened_files() as opened:
        character, _ = read_character(tmp_path / "body.ply", allow_external_files=True)
        hair = read_hair(tmp_path / "hair.ply", limits=ALLOWED)
    assert (character.n_vertices, hair.n_particles) == (3, 3)
    assert str(tmp_path / "body.ply") in opened and str(tmp_path / "skin.png") not in opened
