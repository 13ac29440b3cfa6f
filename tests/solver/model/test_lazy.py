"""Tests for solver/model/lazy.py: a package's names imported on first use."""

from __future__ import annotations

import sys

import pytest

from hairport.solver.model.lazy import export_sources


@pytest.fixture
def package(tmp_path, monkeypatch):
    """A package ``lazy_probe`` handing out ``value`` from ``heavy`` and ``other:renamed`` from ``light``."""
    root = tmp_path / "lazy_probe"
    root.mkdir()
    (root / "__init__.py").write_text(
        "from hairport.solver.model.lazy import lazy_exports\n"
        "__all__, __getattr__, __dir__ = lazy_exports(__name__, {'heavy': ('value',), 'light': ('other:renamed',)})\n")
    (root / "heavy.py").write_text("value = [42]\n")
    (root / "light.py").write_text("renamed = 'light'\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    yield
    for name in [name for name in sys.modules if name.split(".")[0] == "lazy_probe"]:
        del sys.modules[name]


def test_names_are_imported_on_first_use_and_kept(package):
    import lazy_probe

    assert lazy_probe.__all__ == ["other", "value"]
    assert "lazy_probe.heavy" not in sys.modules and "lazy_probe.light" not in sys.modules
    assert {"other", "value"} <= set(dir(lazy_probe))
    value = lazy_probe.value
    assert value == [42] and "lazy_probe.heavy" in sys.modules and "lazy_probe.light" not in sys.modules
    assert vars(lazy_probe)["value"] is value  # kept: the next use is a plain attribute
    from lazy_probe import other

    assert other == "light"


def test_an_unknown_name_is_an_attribute_error_and_a_submodule_still_imports(package):
    import lazy_probe

    with pytest.raises(AttributeError, match="'lazy_probe' has no attribute 'valeu'"):
        lazy_probe.valeu  # noqa: B018
    from lazy_probe import light

    assert light.renamed == "light"


def test_a_name_handed_out_twice_is_refused():
    assert export_sources("p", {"a": ("x", "y:z")}) == {"x": ("p.a", "x"), "y": ("p.a", "z")}
    with pytest.raises(ValueError, match="hands out 'x' twice"):
        export_sources("p", {"a": ("x",), "b": ("x",)})
    with pytest.raises(TypeError, match="a string, not a tuple"):
        export_sources("p", {"a": ("x")})
