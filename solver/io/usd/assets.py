"""Every file a USD layer names, found on the layer alone, before anything is composed.

:func:`asset_names` walks one opened ``Sdf.Layer`` (text or crate: Sdf reads both alike) and
yields every non-empty asset path it holds, with the kind of link and the spec holding it:

- the layer's ``subLayers`` (``sublayer``);
- on every spec (prims, variant sets and their variants, attributes, relationships, the layer
  itself) every metadata field: the items of ``references`` and ``payload`` list operations
  (internal ones, to a prim of the same layer, hold no asset path and pass), value clips
  (``clips`` dictionaries, the older ``clipAssetPaths``...; a clip template is a string whose key
  says it is an asset path), and any asset path in a dictionary (``assetInfo``, ``customData``,
  ``customLayerData``);
- every attribute's ``default`` and each of its time samples holding an ``asset`` or ``asset[]``
  value (textures, and anything else USD's resolver would look up).

``inherits`` and ``specializes`` name prim paths, not files: a class in another layer comes in
through a sublayer or reference, which the walk finds. Nothing here resolves or opens a name.
"""

from __future__ import annotations

from collections.abc import Iterator

#: the kind of link each metadata field is, in messages (other fields: "asset path in FIELD")
FIELD_KINDS = {
    "references": "reference",
    "payload": "payload",
    "clips": "value clip",
    "clipAssetPaths": "value clip",
    "clipManifestAssetPath": "value clip",
    "clipTemplateAssetPath": "value clip",
    "default": "asset-valued attribute",
    "timeSamples": "asset-valued attribute",
}
#: fields the walk leaves to :func:`asset_names` itself: sublayers (read from the layer, with their
#: offsets, which have no Python form) and time samples (read one at a time, not all at once)
OWN_FIELDS = ("subLayers", "subLayerOffsets", "timeSamples")
#: a string under a dictionary key or field ending so is an asset path (clip templates are strings)
ASSET_PATH_KEYS = ("assetpath", "assetpaths")
#: the list operations' item lists, every one of which may name a layer
LIST_OP_ITEMS = ("explicitItems", "addedItems", "prependedItems", "appendedItems", "orderedItems", "deletedItems")


def asset_names(layer) -> Iterator[tuple[str, str, str]]:
    """``(kind, spec path, asset path)`` of every file ``layer`` names (module notes), sublayers first.

    Parameters
    ----------
    layer : Sdf.Layer
        Opened alone (``Sdf.Layer.OpenAsAnonymous``): nothing it names has been opened.

    Yields
    ------
    kind : str
        ``"sublayer"``, ``"reference"``, ``"payload"``, ``"value clip"``, ``"asset-valued attribute"``
        or ``"asset path in FIELD"``.
    where : str
        The path of the spec holding it (``"/"`` for the layer).
    name : str
        The asset path as authored.
    """
    from pxr import Sdf

    for name in layer.subLayerPaths:
        if name:
            yield "sublayer", "/", name
    paths: list = []
    layer.Traverse(Sdf.Path.absoluteRootPath, paths.append)
    for path in paths:
        spec = layer.GetObjectAtPath(path)
        if spec is None:
            continue
        for field in spec.ListInfoKeys():
            if field in OWN_FIELDS:
                continue
            try:
                value = spec.GetInfo(field)
            except TypeError:  # a field type without a Python form (layer offsets): it names no file
                continue
            kind = FIELD_KINDS.get(field, f"asset path in {field}")
            for name in _names_in(value, field, Sdf):
                yield kind, str(path), name
        for time in layer.ListTimeSamplesForPath(path):
            for name in _names_in(layer.QueryTimeSample(path, time), "timeSamples", Sdf):
                yield FIELD_KINDS["timeSamples"], str(path), name


def _names_in(value, field: str, Sdf) -> Iterator[str]:
    """Every non-empty asset path in one field's value, dictionaries and lists included (a stack,
    not recursion: a hostile file nests dictionaries as deep as it likes)."""
    stack = [(value, field)]
    while stack:
        value, key = stack.pop()
        if isinstance(value, Sdf.AssetPath):
            name = _authored(value)
            if name:
                yield name
        elif isinstance(value, Sdf.AssetPathArray):
            yield from (name for name in map(_authored, value) if name)
        elif isinstance(value, (Sdf.Reference, Sdf.Payload)):
            if value.assetPath:
                yield value.assetPath
        elif isinstance(value, (Sdf.ReferenceListOp, Sdf.PayloadListOp)):
            stack.extend((item, key) for items in LIST_OP_ITEMS for item in getattr(value, items))
        elif isinstance(value, dict):
            stack.extend((item, name) for name, item in value.items())
        elif isinstance(value, (list, tuple)):
            stack.extend((item, key) for item in value)
        elif isinstance(value, str) and value and str(key).lower().endswith(ASSET_PATH_KEYS):
            yield value


def _authored(asset) -> str:
    """The asset path as written in the file (USD before 0.25 has ``path`` only)."""
    return getattr(asset, "authoredPath", None) or asset.path
