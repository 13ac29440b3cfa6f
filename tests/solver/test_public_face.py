"""The public face of the solver: every name it hands out resolves to its module's own object, imported on first
use, and the outer packages use no solver name the face does not hand out."""

import ast
import importlib
import re
import subprocess
import sys
from pathlib import Path

import pytest

import hairport.solver as solver

ROOT = Path(__file__).resolve().parents[2]
#: the named public modules the outer packages import by name (the contracts protect every other)
PUBLIC_MODULES = {"options", "display", "documents", "distributed", "kernels", "render", "synthetic"}


def test_every_name_of_the_face_resolves_to_its_modules_own_object():
    assert len(solver.__all__) == len(set(solver.__all__)) and 30 <= len(solver.__all__) <= 60
    for module, entries in solver.PUBLIC_NAMES.items():
        for entry in entries:
            name, _, attribute = entry.partition(":")
            assert getattr(solver, name) is getattr(importlib.import_module(f"hairport.solver.{module}"),
                                                    attribute or name), name
    assert set(solver.__all__) <= set(dir(solver))
    assert solver.HAIR_FORMATS == ("data", "hair", "ply", "npz", "obj", "usd", "usda", "usdc", "abc")
    assert solver.UNITS == ("m", "dm", "cm", "mm")
    with pytest.raises(AttributeError, match="no attribute 'retargett'"):
        solver.retargett  # noqa: B018


@pytest.mark.parametrize("parser", ["hairport.solver.io.hair.sandboxed", "hairport.solver.io.character.usd",
                                    "hairport.solver.io.character.alembic"])
def test_a_file_parser_loads_no_solver_beyond_what_it_imports(parser):
    # a sandboxed read is a child process per file: importing the face and a parser must not load the solve, the
    # compiled kernels' modules or the character loader
    probe = (f"import sys, hairport.solver, {parser}; print(sorted(m for m in ('numba', 'osqp', "
             "'hairport.solver.pipeline', 'hairport.solver.io.character.load') if m in sys.modules))")
    loaded = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True, cwd=ROOT)
    assert loaded.stdout.strip() == "[]"


def test_the_outer_packages_use_only_the_faces_names_and_its_public_modules():
    # attribute uses of the imported face (``solver.name``), not dotted paths in docstrings (``hairport.solver.io``)
    used = {}
    for top in ("hairport", "service", "worker"):
        for path in (ROOT / top).rglob("*.py"):
            for name in re.findall(r"(?<![\w.])solver\.([A-Za-z_]\w*)", path.read_text()):
                used.setdefault(name, path.relative_to(ROOT).as_posix())
    unknown = {name: where for name, where in used.items()
               if name not in solver.__all__ and name not in PUBLIC_MODULES}
    assert unknown == {}


def outer_attribute_uses():
    """``(file, alias, module, attribute)`` for every ``alias.attribute`` in the outer packages where ``alias`` is
    the solver or one of its modules imported by ``from hairport import solver`` / ``from hairport.solver import x``."""
    for top in ("hairport", "service", "worker"):
        for path in (ROOT / top).rglob("*.py"):
            tree = ast.parse(path.read_text())
            aliases = {}
            for node in ast.walk(tree):
                if isinstance(node, ast.ImportFrom) and node.module in ("hairport", "hairport.solver"):
                    for alias in node.names:
                        name = alias.name if node.module == "hairport.solver" else "solver" if alias.name == "solver" else None
                        if name is not None:
                            aliases[alias.asname or alias.name] = "hairport.solver" if name == "solver" else f"hairport.solver.{name}"
            for node in ast.walk(tree):
                if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases:
                    yield path.relative_to(ROOT).as_posix(), node.value.id, aliases[node.value.id], node.attr


def test_every_solver_name_the_outer_packages_use_exists_where_they_take_it():
    missing = set()
    for where, alias, module, attribute in outer_attribute_uses():
        try:
            target = importlib.import_module(module)
        except ImportError:
            continue  # a name imported from the face, not a module
        if not hasattr(target, attribute):
            missing.add(f"{where}: {alias}.{attribute}")
    assert missing == set()
