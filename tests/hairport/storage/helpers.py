"""Helpers shared by the storage tests."""


def blob_files(root):
    return sorted(p for p in (root / "blobs").rglob("*") if p.is_file())
