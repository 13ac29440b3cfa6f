"""Indexes: sorted names with a tag, one empty file each, so that listings read no documents.

An index entry is the empty file ``root/index/<index>/<group>/<key>.<tag>``: a listing of a
group is one directory scan (names only), sorted by key, filtered by tag. Keys and tags are
storage names (:func:`.layout.check_name`); the caller keeps an entry in step with the
document it indexes (e.g. under that document's lock) and drops entries whose document is gone.
"""

from __future__ import annotations

import os
from pathlib import Path

from .layout import FILE_MODE, _subdirs, _unlink, check_name


class IndexStore:
    """Index entries under ``root/index``."""

    root: Path

    def index_put(self, index: str, group: str, key: str, tag: str, old_tag: str | None = None) -> None:
        """Give ``key`` the tag ``tag`` in ``group`` (renaming its entry of tag ``old_tag``, or any other)."""
        folder = self._index_folder(index, group)
        folder.mkdir(parents=True, exist_ok=True)
        target = folder / f"{check_name(key, 'index key')}.{check_name(tag, 'index tag')}"
        old = [folder / f"{key}.{old_tag}"] if old_tag is not None else []
        for source in old + self._entries_of(folder, key):
            if source == target:
                return
            try:
                os.replace(source, target)
                return
            except FileNotFoundError:
                continue
        os.close(os.open(target, os.O_WRONLY | os.O_CREAT, FILE_MODE))

    def index_drop(self, index: str, group: str, key: str) -> None:
        """Remove ``key``'s entry (whatever its tag)."""
        for entry in self._entries_of(self._index_folder(index, group), key):
            _unlink(entry)

    def index_entries(self, index: str, group: str) -> list[tuple[str, str]]:
        """``(key, tag)`` of every entry of ``group``, in no particular order."""
        try:
            with os.scandir(self._index_folder(index, group)) as entries:
                names = [entry.name for entry in entries if not entry.name.startswith(".")]
        except FileNotFoundError:
            return []
        return [tuple(name.rsplit(".", 1)) for name in names if "." in name]

    def index_groups(self, index: str) -> list[str]:
        """The groups of ``index`` that have a folder."""
        return sorted(folder.name for folder in _subdirs(self.root / "index" / check_name(index, "index")))

    def _index_folder(self, index: str, group: str) -> Path:
        return self.root / "index" / check_name(index, "index") / check_name(group, "index group")

    @staticmethod
    def _entries_of(folder: Path, key: str) -> list[Path]:
        try:
            with os.scandir(folder) as entries:
                return [Path(entry.path) for entry in entries if entry.name.rsplit(".", 1)[0] == key]
        except FileNotFoundError:
            return []
