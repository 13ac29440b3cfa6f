"""The package as a studio installs it: the wheel carries the dashboard's bundle (built from dashboard/ by the
build backend, git-ignored), and the build asks for Node.js from PyPI only on a machine without one."""

import importlib.util
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).parents[2]


def build_backend():
    spec = importlib.util.spec_from_file_location("hairport_build", ROOT / "build_backend" / "hairport_build.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


def test_the_wheel_carries_the_dashboard_bundle(tmp_path):
    subprocess.run([sys.executable, "-m", "pip", "wheel", str(ROOT), "--no-deps", "-q",
                    "-w", str(tmp_path)], check=True, capture_output=True)
    wheel = next(tmp_path.glob("hairport-*.whl"))
    names = set(zipfile.ZipFile(wheel).namelist())
    for name in ("index.html", "app.js", "style.css", "build.json"):
        assert f"hairport/service/dashboard/{name}" in names
    bundle = zipfile.ZipFile(wheel).read("hairport/service/dashboard/app.js")
    assert len(bundle) > 300_000 and b"WebGLRenderer" in bundle  # three.js is in it
    assert not any(name.startswith(("dashboard/", "hairport/dashboard/node_modules")) for name in names)


def test_node_comes_from_pypi_only_on_a_machine_without_one(monkeypatch):
    backend = build_backend()
    monkeypatch.setattr(backend.shutil, "which", lambda program: None)
    assert backend.NODE_WHEEL in backend.get_requires_for_build_wheel()
    assert backend.NODE_WHEEL in backend.get_requires_for_build_editable()
    monkeypatch.setattr(backend.shutil, "which", lambda program: f"/usr/bin/{program}")
    assert backend.NODE_WHEEL not in backend.get_requires_for_build_wheel()
    assert backend.node_command("npm") == ["/usr/bin/npm"]
