"""The public face of the solver: every name it hands out is imported explicitly (so the import graph, and
the contracts on it, see it), and the outer packages use no solver name the face does not hand out."""

import ast
import importlib
import re
from pathlib import Path

import hairport.solver as solver

ROOT = Path(__file__).resolve().parents[2]
#: the named public modules the outer packages import by name (the contracts protect every other)
PUBLIC_MODULES = {"options", "display", "documents", "distributed", "kernels", "render", "synthetic"}


def test_every_name_of_the_face_is_imported_explicitly_and_resolves():
    tree = ast.parse((ROOT / "solver" / "__init__.py").read_text())
    imported = {alias.asname or alias.name for node in tree.body if isinstance(node, ast.ImportFrom)
                for alias in node.names}
    functions = {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}
    assert "__getattr__" not in functions and "importlib" not in (ROOT / "solver" / "__init__.py").read_text()
    assert set(solver.__all__) == imported - {"annotations"}
    assert len(solver.__all__) == len(set(solver.__all__)) and 30 <= len(solver.__all__) <= 60
    for name in solver.__all__:
        assert getattr(solver, name) is not None, name
    assert solver.HAIR_FORMATS == ("data", "hair", "ply", "npz", "obj", "usd", "usda", "usdc", "abc")
    assert solver.UNITS == ("m", "dm", "cm", "mm")


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
