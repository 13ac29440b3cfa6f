"""The README's quick start runs as written: its curl walk-through, pasted as one block into bash, starts a
real ``hairport serve --embedded``, retargets the demo's groom and downloads a result that reads back as
the demo's hairstyle.

The block runs in a temporary working directory after ``hairport demo`` wrote its files there, with
``XDG_DATA_HOME`` and ``HAIRPORT_STORAGE_DIR`` in temporary folders (nothing touches the user's storage),
an unreachable ``HAIRPORT_REDIS_URL`` (the embedded mode needs no Redis), and ``PORT`` a free port."""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from hairport.cli.demo import DEFAULT_PARTICLES, DEFAULT_STRANDS

README = Path(__file__).resolve().parents[2] / "README.md"
#: the marker the README puts before the quick start's fenced block
MARKER = "<!-- quickstart -->"
#: the demo's groom (``hairport demo`` defaults): strands, and particles in all
DEMO_STRANDS, DEMO_PARTICLES = DEFAULT_STRANDS, DEFAULT_PARTICLES * DEFAULT_STRANDS
#: bound on the whole block (server start, uploads, preprocessing, one small retarget): a hang guard, not
#: a timing assertion
BLOCK_LIMIT_SECONDS = 600


def quickstart_block() -> str:
    """The bash block right after the README's quick-start marker."""
    text = README.read_text()
    match = re.search(re.escape(MARKER) + r"\s*\n```bash\n(.*?)\n```", text, re.S)
    assert match, f"README.md has no ```bash block after {MARKER}"
    return match.group(1)


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_the_block_is_one_guarded_script():
    block = quickstart_block()
    # pasted whole it runs in a subshell with errexit, downloads only with --fail, and stops its server
    assert block.startswith("(\nset -euo pipefail\n") and block.endswith("\n)")
    assert "--fail" in block and "trap " in block and "hairport serve --embedded" in block
    assert not re.search(r"\|\s*jq\b", block)  # JSON fields by python3, not jq (no jq on a fresh machine)


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> tuple[Path, dict]:
    """A working directory holding ``hairport-demo/``, and the environment the block runs in."""
    root = tmp_path_factory.mktemp("readme")
    work = root / "work"
    work.mkdir()
    env = {**os.environ, "XDG_DATA_HOME": str(root / "data"), "HAIRPORT_STORAGE_DIR": str(root / "storage"),
           "HAIRPORT_REDIS_URL": "redis://127.0.0.1:1/0", "PORT": str(free_port()),
           # the installed console script of this interpreter first
           "PATH": os.pathsep.join((str(Path(sys.executable).parent), os.environ.get("PATH", "")))}
    for name in ("HAIRPORT_API_KEYS", "HAIRPORT_INSECURE_DEV"):
        env.pop(name, None)
    demo = subprocess.run(["hairport", "demo", "--quiet", "--out", "hairport-demo"], cwd=work, env=env,
                          capture_output=True, text=True)
    assert demo.returncode == 0, demo.stderr
    return work, env


def test_the_quickstart_runs_as_written_and_downloads_the_result(workdir):
    from hairport.solver import read_hair

    work, env = workdir
    process = subprocess.Popen(["bash", "-euo", "pipefail", "-c", quickstart_block()], cwd=work, env=env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        out, err = process.communicate(timeout=BLOCK_LIMIT_SECONDS)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        out, err = process.communicate()
    log = (work / "hairport-serve.log").read_text() if (work / "hairport-serve.log").exists() else ""
    assert process.returncode == 0, f"{out}\n{err}\n{log[-3000:]}"
    assert re.search(r"job [0-9a-f]+ succeeded: result\.ply, preview\.png", out)

    result = read_hair(work / "result.ply")
    source = read_hair(work / "hairport-demo" / "source_hair.hair")
    assert (result.n_strands, result.n_particles) == (source.n_strands, source.n_particles)
    assert (result.n_strands, result.n_particles) == (DEMO_STRANDS, DEMO_PARTICLES)
    # the roots moved from the average female's scalp to the heavy male's
    assert abs(result.points - source.points).max() > 1e-3
    assert (work / "preview.png").read_bytes().startswith(b"\x89PNG")
    # the block stopped its server: the port is free again
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", int(env["PORT"])))


def test_a_failed_job_fails_the_block_and_saves_no_result(workdir):
    """The same block with a hairline curve far off the head: the job fails (``off_head``), the block exits 1
    naming the code, and no result file is written."""
    work, env = workdir
    request = r'\"output_format\": \"ply\"}'
    block = quickstart_block()
    assert request in block
    bad = block.replace(request, r'\"output_format\": \"ply\", \"hairline\": {\"curve\": {\"units\": \"m\", '
                                 r'\"points\": [[0, 5, 0], [0.1, 5, 0], [0.2, 5, 0]]}}}')
    folder = work / "failing"
    folder.mkdir()
    (folder / "hairport-demo").symlink_to(work / "hairport-demo")
    failing = subprocess.run(["bash", "-euo", "pipefail", "-c", bad], cwd=folder, env={**env, "PORT": str(free_port())},
                             capture_output=True, text=True, timeout=BLOCK_LIMIT_SECONDS)
    assert failing.returncode == 1, failing.stderr
    assert re.search(r"job [0-9a-f]+: failed off_head ", failing.stderr)
    assert not (folder / "result.ply").exists() and not (folder / "preview.png").exists()


def test_a_refused_upload_fails_the_block_and_prints_the_problem(workdir):
    """The same block with a hair file that is not one: the upload is refused (422), the block exits 1 and
    prints the API's problem (its code), and nothing is downloaded."""
    work, env = workdir
    folder = work / "refused"
    (folder / "hairport-demo").mkdir(parents=True)
    for item in (work / "hairport-demo").iterdir():
        (folder / "hairport-demo" / item.name).symlink_to(item)
    (folder / "hairport-demo" / "source_hair.hair").unlink()
    (folder / "hairport-demo" / "source_hair.hair").write_bytes(b"HAIR" + b"\xff" * 60)
    refused = subprocess.run(["bash", "-euo", "pipefail", "-c", quickstart_block()], cwd=folder,
                             env={**env, "PORT": str(free_port())}, capture_output=True, text=True,
                             timeout=BLOCK_LIMIT_SECONDS)
    assert refused.returncode != 0
    problem = re.search(r'\{"type":.*"status":422.*"code":"(\w+)"', refused.stderr)
    assert problem, refused.stderr
    assert problem.group(1) in {"truncated", "bad_header"}
    assert not (folder / "result.ply").exists() and not (folder / "preview.png").exists()
