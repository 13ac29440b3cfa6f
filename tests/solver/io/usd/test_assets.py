"""Every file a USD layer names (solver/io/usd/assets.py), found on the layer alone: each kind of link, in
text and crate layers, and nothing for the links that stay inside the layer."""

from __future__ import annotations

import pytest
from pxr import Sdf

from hairport.solver.io.usd.assets import asset_names

HEADER = "#usda 1.0\n(\n    metersPerUnit = 1\n)\n\n"
#: (layer body after the header, the (kind, spec path, asset path) the walk finds)
LINKS = {
    "reference": ('def Xform "Groom" (\n    prepend references = @/srv/a.usda@</Groom>\n)\n{\n}\n',
                  [("reference", "/Groom", "/srv/a.usda")]),
    "payload": ('def Xform "Groom" (\n    payload = @../b.usdc@\n)\n{\n}\n', [("payload", "/Groom", "../b.usdc")]),
    "deleted reference": ('over "Groom" (\n    delete references = @/srv/c.usda@\n)\n{\n}\n',
                          [("reference", "/Groom", "/srv/c.usda")]),
    "value clips": ('def Xform "Groom" (\n    clips = {\n        dictionary default = {\n'
                    '            double2[] active = [(0, 0)]\n            asset[] assetPaths = [@/srv/clip.usda@]\n'
                    '            asset manifestAssetPath = @/srv/manifest.usda@\n'
                    '            string primPath = "/Groom"\n        }\n    }\n)\n{\n}\n',
                    [("value clip", "/Groom", "/srv/clip.usda"), ("value clip", "/Groom", "/srv/manifest.usda")]),
    "clip template": ('def Xform "Groom" (\n    clips = {\n        dictionary default = {\n'
                      '            string templateAssetPath = "/srv/clip.###.usda"\n'
                      '            double templateStartTime = 0\n        }\n    }\n)\n{\n}\n',
                      [("value clip", "/Groom", "/srv/clip.###.usda")]),
    "asset attribute": ('def Scope "Material"\n{\n    asset file = @/etc/passwd@\n'
                        '    asset[] more = [@/etc/hosts@]\n}\n',
                        [("asset-valued attribute", "/Material.file", "/etc/passwd"),
                         ("asset-valued attribute", "/Material.more", "/etc/hosts")]),
    "asset time samples": ('def Scope "Material"\n{\n    asset file.timeSamples = {\n        1: @/srv/t1.png@,\n'
                           '        2: @/srv/t2.png@,\n    }\n}\n',
                           [("asset-valued attribute", "/Material.file", "/srv/t1.png"),
                            ("asset-valued attribute", "/Material.file", "/srv/t2.png")]),
    "metadata": ('def Xform "Groom" (\n    assetInfo = {\n        asset identifier = @/srv/info.usda@\n    }\n'
                 '    customData = {\n        dictionary deep = {\n            asset x = @/srv/deep.usda@\n'
                 '        }\n    }\n)\n{\n}\n',
                 [("asset path in assetInfo", "/Groom", "/srv/info.usda"),
                  ("asset path in customData", "/Groom", "/srv/deep.usda")]),
    "variant": ('def Xform "Groom" (\n    variants = {\n        string look = "long"\n    }\n'
                '    prepend variantSets = "look"\n)\n{\n    variantSet "look" = {\n'
                '        "long" (\n            prepend references = @/srv/long.usda@\n        ) {\n'
                '            def "Inner" (\n                payload = @/srv/inner.usda@\n            )\n'
                '            {\n            }\n        }\n    }\n}\n',
                [("reference", "/Groom{look=long}", "/srv/long.usda"),
                 ("payload", "/Groom{look=long}Inner", "/srv/inner.usda")]),
}


def layer_of(body: str, header: str = HEADER):
    layer = Sdf.Layer.CreateAnonymous(".usda")
    assert layer.ImportFromString(header + body)
    return layer


@pytest.mark.parametrize("link", sorted(LINKS))
def test_every_kind_of_link_is_found_with_its_spec(link):
    body, expected = LINKS[link]
    assert sorted(asset_names(layer_of(body))) == sorted(expected)


def test_sublayers_come_first_and_in_order():
    header = '#usda 1.0\n(\n    subLayers = [\n        @/srv/one.usda@,\n        @./two.usda@\n    ]\n)\n\n'
    found = list(asset_names(layer_of(LINKS["reference"][0], header)))
    assert found == [("sublayer", "/", "/srv/one.usda"), ("sublayer", "/", "./two.usda"),
                     ("reference", "/Groom", "/srv/a.usda")]


def test_a_crate_layer_is_walked_alike(tmp_path):
    header = '#usda 1.0\n(\n    subLayers = [\n        @/srv/groom.usda@\n    ]\n)\n\n'
    layer_of(LINKS["payload"][0], header).Export(str(tmp_path / "groom.usdc"))
    assert (tmp_path / "groom.usdc").read_bytes().startswith(b"PXR-USDC")
    found = list(asset_names(Sdf.Layer.OpenAsAnonymous(str(tmp_path / "groom.usdc"))))
    assert found == [("sublayer", "/", "/srv/groom.usda"), ("payload", "/Groom", "../b.usdc")]


def test_links_inside_the_layer_name_no_file():
    body = ('class "_hair"\n{\n    float width = 1\n}\n\n'
            'def Xform "Groom" (\n    inherits = </_hair>\n    specializes = </_hair>\n'
            '    prepend references = </_hair>\n    payload = </_hair>\n    assetInfo = {\n'
            '        string name = "groom"\n    }\n)\n{\n    asset nothing = @@\n    string file = "/etc/passwd"\n}\n')
    assert list(asset_names(layer_of(body))) == []
