"""Where the parsed MakeHuman assets live in a process: one store per assets directory.

A store parses (or loads from the ``.npz`` caches) the base model and each target folder on
first use and keeps them, so that later builds in the process take a few milliseconds.
Stores are shared by every thread; each guards its lazy loading with a lock.
"""

from __future__ import annotations

import difflib
import threading
from pathlib import Path

from hairport.solver.model.errors import InputError
from hairport.solver.synthetic.assets import BASE_OBJ, fetch_makehuman_assets
from hairport.solver.synthetic.makehuman.base_model import BaseModel, base_model_from_arrays, parse_base_model
from hairport.solver.synthetic.makehuman.cache import PARSED_DIR, load_cache, save_cache
from hairport.solver.synthetic.makehuman.macros import SHAPE_TARGET_GROUPS, MakeHumanParams
from hairport.solver.synthetic.makehuman.targets import TargetGroup, target_files, target_name

#: cache file of the parsed base model, under ``<assets>/parsed/``
BASE_MODEL_CACHE = "base-model.npz"


class AssetStore:
    """Per-assets-directory, in-process cache of the base model and parsed target groups."""

    def __init__(self, assets: Path):
        self.assets = assets
        self._lock = threading.Lock()
        self._model: BaseModel | None = None
        self._groups: dict[str, TargetGroup] = {}

    @property
    def model(self) -> BaseModel:
        with self._lock:
            if self._model is None:
                cache = self.assets / PARSED_DIR / BASE_MODEL_CACHE
                arrays = load_cache(cache)
                if arrays is None:
                    arrays = parse_base_model(self.assets)
                    save_cache(cache, arrays)
                self._model = base_model_from_arrays(arrays)
            return self._model

    def group(self, group: str) -> TargetGroup:
        with self._lock:
            if group not in self._groups:
                self._groups[group] = TargetGroup(self.assets, group)
            return self._groups[group]

    def available_targets(self, group: str) -> tuple[str, ...]:
        """The names of the targets of folder ``group``, sorted."""
        return tuple(sorted(target_name(group, p) for p in target_files(self.assets, group)))


_STORES: dict[Path, AssetStore] = {}
_STORES_LOCK = threading.Lock()


def asset_store(assets_dir: Path | None) -> AssetStore:
    """The store of an assets directory (default: fetched into the default cache).

    Raises
    ------
    InputError
        ``missing_assets`` when the directory holds no base mesh.
    """
    assets = Path(assets_dir) if assets_dir is not None else fetch_makehuman_assets()
    assets = assets.resolve()
    if not (assets / BASE_OBJ).is_file():
        raise InputError(f"no MakeHuman assets in {assets} (expected {BASE_OBJ})", str(assets), "missing_assets")
    with _STORES_LOCK:
        if assets not in _STORES:
            _STORES[assets] = AssetStore(assets)
        return _STORES[assets]


def available_targets(assets_dir: Path | None = None) -> tuple[str, ...]:
    """Names accepted in :attr:`MakeHumanParams.targets` (e.g. ``"head/head-round"``)."""
    store = asset_store(assets_dir)
    return tuple(name for group in SHAPE_TARGET_GROUPS for name in store.available_targets(group))


def check_extra_targets(store: AssetStore, params: MakeHumanParams) -> None:
    """Refuse a shape target of ``params`` that the assets do not have (``unknown_target``), with close matches."""
    for name, _ in params.targets:
        group = name.rsplit("/", 1)[0]
        known = store.available_targets(group)
        if name not in known:
            close = difflib.get_close_matches(name, known, n=3)
            hint = f"; did you mean {', '.join(repr(c) for c in close)}?" if close else ""
            raise InputError(f"unknown shape target {name!r}{hint}", "targets", "unknown_target")
