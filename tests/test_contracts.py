"""The import-linter contracts can fail: modules planted in a scratch copy of the layout (never in the
repository) that break them are reported by name, and an import of a public module is not."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: planted module -> its one line of source, each a deliberate edge across a contract
VIOLATIONS = {
    "hairport.service.planted_pipeline": "from hairport.solver.pipeline import retarget",
    "hairport.worker.planted_jit": "from hairport.solver import jit",
    "hairport.cli.planted_internals": "import hairport.solver.mesh.query",
    "hairport.solver.model.planted_upward": "from hairport.solver import pipeline",
}
#: planted modules that import only what the contracts allow
ALLOWED = {
    "hairport.service.planted_public": "from hairport.solver import display, documents, options",
    "hairport.worker.planted_face": "from hairport.solver import retarget",
}


def lint(planted: dict[str, str]) -> subprocess.CompletedProcess:
    arguments = [argument for module, source in planted.items() for argument in ("--plant", f"{module}={source}")]
    return subprocess.run([sys.executable, str(ROOT / ".ci" / "lint-imports"), *arguments], capture_output=True,
                          text=True, timeout=300)


def test_planted_violations_break_their_contracts_and_public_imports_do_not():
    done = lint({**VIOLATIONS, **ALLOWED})
    assert done.returncode == 1, done.stdout
    report = " ".join(done.stdout.split())  # import-linter wraps long lines
    assert "Illegal imports of protected package hairport.solver.pipeline" in report
    assert "hairport.service.planted_pipeline -> hairport.solver.pipeline" in report
    assert "hairport.worker.planted_jit -> hairport.solver.jit" in report
    assert "hairport.cli.planted_internals -> hairport.solver.mesh.query" in report
    # the solver's own layers: the data model may not reach up to the stages
    assert "hairport.solver.model.planted_upward -> hairport.solver.pipeline" in report
    # broken: the protected solver, the solver's layers, and the acyclic siblings (model <-> pipeline is a circle)
    assert "Contracts: 5 kept, 3 broken." in report
    for module in ALLOWED:
        assert module not in report


def test_the_repository_keeps_every_contract():
    done = lint({})
    assert done.returncode == 0 and "0 broken" in done.stdout, done.stdout
