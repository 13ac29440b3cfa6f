"""Structure of the deployment files: Dockerfile, .dockerignore and docker-compose.yml.

These tests read the files only (no Docker needed). They pin what the deployment relies on:
API and workers run one image and share one storage volume, talk to the same Redis, wait
for Redis to be healthy, are health-checked, and the commands they run are valid
``hairport`` command lines.
"""

from __future__ import annotations

import json
import re
import shlex
import subprocess
import tomllib
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
DOCKERFILE = ROOT / "Dockerfile"
DOCKERIGNORE = ROOT / ".dockerignore"
COMPOSE = ROOT / "docker-compose.yml"



def build_inputs() -> set[str]:
    """What building the package reads (the sdist's contents): pyproject.toml and its readme and build
    backend, the licence files, the package folders, MANIFEST.in and what it includes."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())
    inputs = {"pyproject.toml", "MANIFEST.in", project["project"]["readme"], "LICENSE", "NOTICE",
              *project["build-system"]["backend-path"]}
    inputs |= {folder.split("/")[0] for folder in project["tool"]["setuptools"]["package-dir"].values()}
    for line in (ROOT / "MANIFEST.in").read_text().splitlines():
        words = line.split()
        if words and words[0] == "include":
            inputs |= set(words[1:])
        elif words and words[0] == "recursive-include":
            inputs.add(words[1])
    return inputs


SOURCE_ITEMS = build_inputs()
REDIS_URL = "redis://redis:6379/0"
STORAGE = "/data"


# ---------------------------------------------------------------------------- helpers


@pytest.fixture(scope="module")
def compose() -> dict:
    data = yaml.safe_load(COMPOSE.read_text())
    assert isinstance(data, dict)
    return data


@pytest.fixture(scope="module")
def services(compose) -> dict:
    return compose["services"]


def _instructions(text: str) -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) of a Dockerfile, continuation lines joined, comments dropped."""
    logical, current = [], ""
    for raw in text.splitlines():
        line = raw.strip()
        if not current and (not line or line.startswith("#")):
            continue
        if current and line.startswith("#"):
            continue
        if line.endswith("\\"):
            current += line[:-1] + " "
            continue
        current += line
        logical.append(current)
        current = ""
    if current:
        logical.append(current)
    out = []
    for line in logical:
        keyword, _, args = line.partition(" ")
        out.append((keyword.upper(), args.strip()))
    return out


@pytest.fixture(scope="module")
def dockerfile() -> list[tuple[str, str]]:
    return _instructions(DOCKERFILE.read_text())


def _args(dockerfile, keyword: str) -> list[str]:
    return [args for kw, args in dockerfile if kw == keyword]


def _command(value) -> list[str]:
    """A compose/Dockerfile command as an argv list (exec form or shell string)."""
    if isinstance(value, list):
        return [str(v) for v in value]
    value = str(value).strip()
    if value.startswith("["):
        return json.loads(value)
    return shlex.split(value)


def _env(service: dict) -> dict[str, str]:
    env = service.get("environment", {})
    if isinstance(env, list):
        env = dict(item.split("=", 1) for item in env)
    return {str(k): str(v) for k, v in env.items()}


def _volume_mounts(service: dict) -> dict[str, str]:
    """target path -> named volume, for the named volumes a service mounts."""
    mounts = {}
    for vol in service.get("volumes", []):
        if isinstance(vol, str):
            source, target = vol.split(":")[:2]
        else:
            source, target = vol.get("source"), vol["target"]
        mounts[target] = source
    return mounts


def _healthcheck_text(service: dict) -> str:
    test = service["healthcheck"]["test"]
    return " ".join(test) if isinstance(test, list) else str(test)


def _depends_on(service: dict) -> dict:
    deps = service.get("depends_on", {})
    if isinstance(deps, list):  # short form: no condition
        return {name: {"condition": "service_started"} for name in deps}
    return deps


# ---------------------------------------------------------------------------- Dockerfile


def test_dockerfile_base_image_is_python_311_slim(dockerfile):
    froms = _args(dockerfile, "FROM")
    assert froms, "no FROM"
    assert froms[-1].split()[0] == "python:3.11-slim"


def test_dockerfile_runs_as_a_non_root_user(dockerfile):
    users = _args(dockerfile, "USER")
    assert users, "the image must switch to a non-root USER"
    user = users[-1].split(":")[0]
    assert user not in {"root", "0"}
    # the USER switch comes after the install (pip needs root) and before CMD
    keywords = [kw for kw, _ in dockerfile]
    last_user = len(keywords) - 1 - keywords[::-1].index("USER")
    assert last_user > max(i for i, (kw, a) in enumerate(dockerfile) if kw == "RUN" and "pip install" in a)
    assert last_user < keywords.index("CMD")


def test_dockerfile_copies_only_the_package_sources(dockerfile):
    copies = _args(dockerfile, "COPY") + _args(dockerfile, "ADD")
    assert copies
    copied = set()
    for args in copies:
        parts = [p for p in _command(args) if not p.startswith("--")]
        sources = parts[:-1]
        for source in sources:
            assert source not in {".", "./", "*"}, f"whole build context copied: COPY {args}"
            copied.add(source.rstrip("/").removeprefix("./"))
    # every input of the build is copied (itself or its folder), and nothing else
    assert {item for item in SOURCE_ITEMS if not any(item == c or item.startswith(c + "/") for c in copied)} == set()
    assert {c for c in copied if not any(c == item or item.startswith(c + "/") or c.startswith(item + "/")
                                         for item in SOURCE_ITEMS)} == set()


def test_dockerfile_installs_the_package_without_pip_cache(dockerfile):
    runs = " && ".join(_args(dockerfile, "RUN"))
    assert re.search(r"pip install --no-cache-dir (\.|\"\.\[alembic\]\")(\s|$)", runs)  # the package, with the Alembic extra
    assert "-e ." not in runs and "--editable" not in runs


def test_dockerfile_storage_volume_port_and_cmd(dockerfile):
    envs = " ".join(_args(dockerfile, "ENV"))
    assert re.search(r"HAIRPORT_STORAGE_DIR[= ]/data(\s|$)", envs)
    assert any(_command(v) == [STORAGE] or v.strip() == STORAGE for v in _args(dockerfile, "VOLUME"))
    assert "8000" in " ".join(_args(dockerfile, "EXPOSE")).split()
    cmds = _args(dockerfile, "CMD")
    assert len(cmds) == 1
    assert cmds[0].startswith("["), "CMD must use the exec form (signals reach the server)"
    assert _command(cmds[0]) == ["hairport", "serve", "--host", "0.0.0.0", "--port", "8000"]


def test_dockerfile_healthcheck_hits_healthz_with_python(dockerfile):
    checks = _args(dockerfile, "HEALTHCHECK")
    assert len(checks) == 1
    check = checks[0]
    assert "http://127.0.0.1:8000/healthz" in check
    assert "curl" not in check and "wget" not in check  # neither is in the slim image
    argv = _command(check[check.index("CMD") + 3:].strip())
    assert argv[:2] == ["python", "-c"]
    compile(argv[2], "<healthcheck>", "exec")


def test_dockerignore_keeps_junk_and_secrets_out():
    patterns = {line.strip() for line in DOCKERIGNORE.read_text().splitlines()
                if line.strip() and not line.startswith("#")}
    for required in (".git", "**/__pycache__", "*.egg-info", ".pytest_cache", "hairport-data",
                     "hairport-demo", ".benchmarks", ".env"):
        assert required in patterns, required
    # what the Dockerfile copies must stay in the build context
    for kept in SOURCE_ITEMS:
        assert kept not in patterns, kept


# ---------------------------------------------------------------------------- compose


def test_compose_has_no_version_key_and_the_four_services(compose, services):
    assert "version" not in compose
    assert {"redis", "api", "worker", "flower"} <= set(services)


def test_redis_is_persistent_and_health_checked(compose, services):
    redis = services["redis"]
    assert redis["image"] == "redis:7.2-alpine"
    assert "redis-cli ping" in _healthcheck_text(redis)
    command = _command(redis["command"])
    assert command[command.index("--appendonly") + 1] == "yes"
    named = _volume_mounts(redis)["/data"]
    assert named in compose["volumes"]
    assert "ports" not in redis, "Redis must not be published on the host"


def test_api_and_worker_share_image_volume_and_redis(compose, services):
    api, worker = services["api"], services["worker"]
    assert api["build"] == worker["build"]
    build = api["build"]
    context = build if isinstance(build, str) else build["context"]
    assert context == "."
    assert api.get("image") == worker.get("image")

    for name in ("api", "worker"):
        service = services[name]
        env = _env(service)
        assert env["HAIRPORT_REDIS_URL"] == REDIS_URL, name
        assert env["HAIRPORT_STORAGE_DIR"] == STORAGE, name
        assert env["HAIRPORT_API_KEYS"] == "${HAIRPORT_API_KEYS:-change-me}", name
        assert _volume_mounts(service).get(STORAGE) == "hairport-data", name
        assert _depends_on(service)["redis"]["condition"] == "service_healthy", name
    assert "hairport-data" in compose["volumes"]
    assert _env(api) == _env(worker)
    # the broker host in the URL is the redis service
    assert REDIS_URL.split("//")[1].split(":")[0] in services


def test_compose_environment_names_are_real_settings(services):
    from hairport.settings import Settings

    fields = set(Settings.model_fields)
    for name in ("api", "worker"):
        for key in _env(services[name]):
            assert key.startswith("HAIRPORT_"), key
            assert key.removeprefix("HAIRPORT_").lower() in fields, f"{key} is not a hairport setting"


def test_visibility_timeout_default_exceeds_task_time_limit(services):
    env = _env(services["worker"])

    def default(value: str) -> int:
        match = re.fullmatch(r"\$\{\w+:-(\d+)\}", value)
        return int(match.group(1) if match else value)

    assert default(env["HAIRPORT_VISIBILITY_TIMEOUT"]) > default(env["HAIRPORT_TASK_TIME_LIMIT"])


def test_api_serves_on_8000_with_a_healthz_liveness_check(services):
    api = services["api"]
    assert _command(api["command"])[:2] == ["hairport", "serve"]
    assert "8000:8000" in [str(p) for p in api["ports"]]
    check = _healthcheck_text(api)
    assert "/healthz" in check and "/readyz" not in check


def test_worker_command_healthcheck_and_grace_period(services):
    worker = services["worker"]
    command = _command(worker["command"])
    assert command[:2] == ["hairport", "worker"]
    assert command[command.index("--queues") + 1] == "preprocess,retarget,fine"
    assert "ports" not in worker
    check = _healthcheck_text(worker)
    assert "celery -A hairport.worker.app:celery_app inspect ping" in check
    assert "$$HOSTNAME" in check  # `$$`: expanded in the container, not by compose
    assert re.search(r"(--timeout|-t) \d+", check)
    assert worker["healthcheck"]["test"][0] == "CMD-SHELL"
    assert worker["stop_grace_period"] == "60s"


def test_compose_commands_are_valid_hairport_command_lines(services):
    from hairport.cli import build_parser

    parser = build_parser()
    api = parser.parse_args(_command(services["api"]["command"])[1:])
    assert (api.command, api.host, api.port) == ("serve", "0.0.0.0", 8000)
    worker = parser.parse_args(_command(services["worker"]["command"])[1:])
    assert worker.command == "worker"
    assert worker.queues == "preprocess,retarget,fine" and worker.concurrency == 2
    # the healthcheck pings the node name the worker gives itself (default --hostname NAME@%h)
    prefix = worker.hostname.split("@")[0]
    assert worker.hostname.endswith("@%h")
    assert f"-d {prefix}@$$HOSTNAME" in _healthcheck_text(services["worker"])
    fine = parser.parse_args(_command(services["fine-worker"]["command"])[1:])
    assert (fine.command, fine.queues, fine.concurrency) == ("worker", "fine", 1)
    assert f"-d {fine.hostname.split('@')[0]}@$$HOSTNAME" in _healthcheck_text(services["fine-worker"])
    assert services["fine-worker"]["profiles"] == ["fine"]  # optional: the worker service consumes fine too


def test_flower_is_optional_and_points_at_the_same_redis(services):
    flower = services["flower"]
    assert flower["image"].startswith("mher/flower:")
    assert "monitoring" in flower["profiles"]
    assert "redis" in _depends_on(flower)
    assert f"--broker={REDIS_URL}" in _command(flower["command"])
    assert any(str(p).endswith("5555:5555") for p in flower["ports"])


def _defaults(text: str) -> str:
    """``text`` with each ``${NAME:-default}`` as compose gives it when NAME is unset."""
    return re.sub(r"\$\{\w+:-([^}]*)\}", r"\1", text)


def test_the_multihost_profile_adds_postgres_and_seaweedfs_and_the_services_take_their_urls(compose, services):
    for name in ("postgres", "seaweedfs"):
        assert services[name]["profiles"] == ["multihost"], name
        assert _volume_mounts(services[name]) and set(_volume_mounts(services[name]).values()) <= set(compose["volumes"])
    for name in ("api", "worker"):
        env = _env(services[name])
        for setting in ("STORAGE_URL", "DATABASE_URL", "S3_ENDPOINT_URL", "S3_ACCESS_KEY_ID", "S3_SECRET_ACCESS_KEY"):
            assert env[f"HAIRPORT_{setting}"] == f"${{HAIRPORT_{setting}:-}}", (name, setting)  # unset: one host
    assert "pg_isready" in _healthcheck_text(services["postgres"])


def test_the_compose_store_signs_with_the_services_s3_settings(compose, services):
    identities = json.loads(_defaults(compose["configs"]["seaweedfs-s3"]["content"]))["identities"]
    assert len(identities) == 1
    credentials = identities[0]["credentials"][0]
    raw = compose["configs"]["seaweedfs-s3"]["content"]
    assert "${HAIRPORT_S3_ACCESS_KEY_ID:-" in raw and "${HAIRPORT_S3_SECRET_ACCESS_KEY:-" in raw
    assert credentials["accessKey"] and credentials["secretKey"]
    seaweedfs = services["seaweedfs"]
    assert [mount["target"] for mount in seaweedfs["configs"]] == ["/etc/seaweedfs/s3.json"]
    command = _command(seaweedfs["command"])
    assert command[0] == "server" and "-s3.config=/etc/seaweedfs/s3.json" in command
    assert any(str(port).endswith(":8333") for port in seaweedfs["ports"])
    # the image runs the version the tests run, and every flag is one that version takes
    from tests.servers.seaweed import find_weed

    weed = find_weed()
    version = subprocess.run([str(weed), "version"], capture_output=True, text=True, check=True).stdout
    assert f" {seaweedfs['image'].rsplit(':', 1)[1]} " in version, version
    accepted = subprocess.run([str(weed), "server", "-h"], capture_output=True, text=True).stderr
    accepted += subprocess.run([str(weed), "server", "-h"], capture_output=True, text=True).stdout
    for flag in command[1:]:
        assert re.search(rf"^\s+{re.escape(flag.split('=')[0])}\b", accepted, re.MULTILINE), flag
