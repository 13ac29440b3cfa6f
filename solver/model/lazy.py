"""A package's public names imported on first use (PEP 562), not with the package.

A package whose ``__init__`` imports every name it hands out makes any import below it load them all: a child
process that reads one file (:mod:`~hairport.solver.io.sandbox`) would load the whole solver and its compiled
kernels' modules for a parser. Such a package lists its names by the module that defines each instead, and takes
its module attributes from :func:`lazy_exports`.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Mapping
from typing import Any


def export_sources(package: str, public: Mapping[str, tuple[str, ...]]) -> dict[str, tuple[str, str]]:
    """Public name -> (module, attribute).

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    public : mapping of str to tuple of str
        Module below ``package`` -> the names it hands out; ``"NAME:ATTRIBUTE"`` hands out the module's
        ``ATTRIBUTE`` as ``NAME``.
    """
    sources = {}
    for module, entries in public.items():
        if isinstance(entries, str):  # ("name") without its comma is a string, not a tuple of one name
            raise TypeError(f"{package}: the names of {module} are a string, not a tuple: {entries!r}")
        for entry in entries:
            name, _, attribute = entry.partition(":")
            if name in sources:
                raise ValueError(f"{package} hands out {name!r} twice")
            sources[name] = (f"{package}.{module}", attribute or name)
    return sources


def lazy_exports(package: str, public: Mapping[str, tuple[str, ...]]
                 ) -> tuple[list[str], Callable[[str], Any], Callable[[], list[str]]]:
    """``(__all__, __getattr__, __dir__)`` of a package handing out ``public`` (:func:`export_sources`), each name
    imported on its first use and kept in the package's namespace after it."""
    sources = export_sources(package, public)

    def module_getattr(name: str) -> Any:
        if name not in sources:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        module, attribute = sources[name]
        value = getattr(importlib.import_module(module), attribute)
        setattr(sys.modules[package], name, value)  # later uses skip this function
        return value

    def module_dir() -> list[str]:
        return sorted({*vars(sys.modules[package]), *sources})

    return sorted(sources), module_getattr, module_dir
