"""The tests mirror the source tree, and the documents name only code that exists."""

import ast
import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SOURCES = ("solver", "hairport", "service", "worker")
#: modules whose tests live elsewhere, and where
TESTED_ELSEWHERE = {
    "solver/__init__.py": "tests/solver/test_public_face.py",
    "solver/io/hair/__init__.py": "tests/solver/io/hair/test_registry.py",
    "solver/io/character/__init__.py": "tests/solver/io/character/test_load.py",
    "solver/synthetic/makehuman/__init__.py": "tests/solver/synthetic/makehuman/test_builder.py",
    "hairport/__init__.py": "tests/hairport/cli/test_ops.py",  # the version, in the OpenAPI document
    "hairport/cli/__init__.py": "tests/hairport/cli/test_main.py",
    "hairport/storage/__init__.py": "tests/hairport/storage/test_layout.py",
    "worker/embedded.py": "tests/integration/test_embedded.py",
    "service/services/characters.py": "tests/service/routers/test_characters.py",
    "service/services/hairstyles.py": "tests/service/routers/test_hairstyles.py",
    "service/services/retargets.py": "tests/service/routers/test_retargets.py",
    "service/services/jobs.py": "tests/service/routers/test_jobs.py",
    "service/services/batches.py": "tests/service/routers/test_batches.py",
    "service/services/display.py": "tests/service/routers/test_jobs.py",
    "service/validation_child.py": "tests/service/test_validation.py",  # the children of the pool it tests
}


def modules_with_code():
    for top in SOURCES:
        for path in sorted((ROOT / top).rglob("*.py")):
            statements = ast.parse(path.read_text()).body
            if path.name == "__main__.py" or (path.name == "__init__.py" and len(statements) <= 1):
                continue  # a package docstring only
            yield path.relative_to(ROOT).as_posix()


def test_every_module_has_its_test_file():
    missing = []
    for module in modules_with_code():
        expected = TESTED_ELSEWHERE.get(module) or str(Path("tests", module).with_name(f"test_{Path(module).name}"))
        if not (ROOT / expected).is_file():
            missing.append(f"{module} -> {expected}")
    assert missing == []


def test_no_module_is_over_about_500_lines():
    long = {module: n for module in modules_with_code() if (n := len((ROOT / module).read_text().splitlines())) > 510}
    assert long == {}


def test_equations_name_existing_functions_and_tests():
    text = (ROOT / "docs" / "equations.md").read_text()
    rows = [line for line in text.splitlines() if re.match(r"\| \d+ \|", line)]
    assert [int(row.split("|")[1]) for row in rows] == list(range(1, 22))
    checked = 0
    for row in rows:
        implemented, tests = row.split("|")[3], row.split("|")[4]
        for path, name in re.findall(r"`(solver/[\w/]+\.py)` `([\w.]+)`", implemented):
            assert re.search(rf"(def|class) {name.split('.')[-1]}\b", (ROOT / path).read_text()), (path, name)
            checked += 1
        current = None
        for path, test in re.findall(r"`((?:solver|quality)/[\w/]+\.py)?(?:::(test_\w+))?`", tests):
            current = path or current
            if test:
                assert f"def {test}(" in (ROOT / "tests" / current).read_text(), (current, test)
                checked += 1
    assert checked >= 50
    beyond = text[text.index("## Beyond the paper"):]
    extra = [line for line in beyond.splitlines() if line.startswith("| ") and not line.startswith("| What")]
    assert len(extra) >= 3
    for row in extra:
        implemented, tests = row.split("|")[2], row.split("|")[3]
        named = re.findall(r"`(solver/[\w/]+\.py)` `([\w.]+)`", implemented)
        assert named, row
        for path, name in named:
            assert re.search(rf"(def|class) {name.split('.')[-1]}\b", (ROOT / path).read_text()), (path, name)
        current = None
        for path, test in re.findall(r"`((?:solver|quality)/[\w/]+\.py)?(?:::(test_\w+))?(?:\[\w+\])?`", tests):
            current = path or current
            assert current and (ROOT / "tests" / current).is_file(), row
            if test:
                assert f"def {test}(" in (ROOT / "tests" / current).read_text(), (current, test)


def test_the_architecture_table_names_existing_packages():
    architecture = (ROOT / "docs" / "architecture.md").read_text()
    section = architecture[architecture.index("## The solver"):architecture.index("## Design decisions")]
    named = re.findall(r"^\| `([\w/.]+)`", section, re.M)
    assert len(named) >= 8
    for name in named:
        assert (ROOT / "solver" / name).exists(), name


def test_every_package_folder_is_installed():
    setup = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    folders = {}
    for name, folder in setup["package-dir"].items():
        for init in (ROOT / folder).rglob("__init__.py"):
            relative = init.parent.relative_to(ROOT / folder).parts
            folders[".".join((name, *relative))] = init.parent
    assert sorted(setup["packages"]) == sorted(folders)
