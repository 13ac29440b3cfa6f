"""A deployment for the integration tests: the environment of a storage folder and a Redis, the FastAPI app
in-process on it, and ``hairport worker`` processes of one child each."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path

import httpx
import pytest

KEY, OTHER_KEY = "test-key-1", "test-key-2"


def service_env(storage: Path, redis_url: str, **settings: str) -> dict:
    """This process's environment with the deployment's: storage, Redis, the two test keys, and ``settings``
    (``HAIRPORT_...`` names)."""
    return {**os.environ, "HAIRPORT_REDIS_URL": redis_url, "HAIRPORT_STORAGE_DIR": str(storage),
            "HAIRPORT_API_KEYS": f"{KEY},{OTHER_KEY}", "HAIRPORT_INSECURE_DEV": "false", **settings}


@contextmanager
def in_process_app(env: dict):
    """``(settings, queue, client)`` of the app built with ``env``'s ``HAIRPORT_`` variables set; the variables
    and the settings cache are restored afterwards."""
    with pytest.MonkeyPatch.context() as patch:
        for name, value in env.items():
            if name.startswith("HAIRPORT_"):
                patch.setenv(name, value)
        from fastapi.testclient import TestClient

        from hairport.service.app import create_app
        from hairport.settings import Settings, get_settings
        from hairport.worker.app import make_celery
        from hairport.worker.queue import TaskQueue

        get_settings.cache_clear()
        settings = Settings()
        queue = TaskQueue(make_celery(settings))
        try:
            yield settings, queue, TestClient(create_app(settings, queue=queue))
        finally:
            get_settings.cache_clear()


def spawn_worker(name: str, env: dict, log_folder: Path, warmup: bool = True) -> subprocess.Popen:
    """A ``hairport worker`` process of one child, hostname ``name@%h``, in a session of its own (for
    ``os.killpg``), its stderr in ``log_folder / f"{name}.log"``."""
    return subprocess.Popen(
        [sys.executable, "-m", "hairport.cli", "worker", *([] if warmup else ["--no-warmup"]), "--concurrency", "1",
         "--hostname", f"{name}@%h", "--loglevel", "WARNING"],
        env=env, stdout=subprocess.DEVNULL, stderr=open(log_folder / f"{name}.log", "wb"), start_new_session=True)


def wait_for_workers(queue, workers: dict[str, subprocess.Popen], logs: dict[str, Path],
                     seconds: float = 90) -> None:
    """Wait until every one of ``workers`` answers on ``queue``; fail with the log (``logs[name]``) of one that
    died, or after ``seconds``."""
    deadline = time.monotonic() + seconds
    while len(set(queue.workers(0.5))) < len(workers):
        assert time.monotonic() < deadline and all(p.poll() is None for p in workers.values()), \
            [logs[name].read_text()[-2000:] for name in workers]


def kill_workers(workers: dict[str, subprocess.Popen]) -> None:
    """SIGKILL every worker still running, and reap them all."""
    for process in workers.values():
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
        process.wait(30)


def spawn_server(env: dict, port: int, log_folder: Path) -> subprocess.Popen:
    """A ``hairport serve`` process on ``port`` in a session of its own, its output in ``log_folder / "serve.log"``."""
    return subprocess.Popen([sys.executable, "-m", "hairport.cli", "serve", "--port", str(port)], env=env,
                            stdout=subprocess.DEVNULL, stderr=open(log_folder / "serve.log", "wb"),
                            start_new_session=True)


def wait_ready(base: str, server: subprocess.Popen, worker: subprocess.Popen, log_folder: Path, worker_name: str,
               seconds: float) -> None:
    """Wait until ``base/readyz`` answers 200; fail with the log of a process that died, or after ``seconds``."""
    deadline = time.monotonic() + seconds
    while True:
        try:
            if httpx.get(f"{base}/readyz", timeout=2).status_code == 200:
                return
        except httpx.HTTPError:
            pass
        assert server.poll() is None, (log_folder / "serve.log").read_text()[-2000:]
        assert worker.poll() is None, (log_folder / f"{worker_name}.log").read_text()[-2000:]
        assert time.monotonic() < deadline, "the server and its worker were not ready"
        time.sleep(0.5)


def stop(process: subprocess.Popen, grace_seconds: float = 20) -> None:
    """Stop a process started in a session of its own (SIGTERM, then SIGKILL after ``grace_seconds``)."""
    if process.poll() is None:
        os.killpg(process.pid, signal.SIGTERM)
    try:
        process.wait(timeout=grace_seconds)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        process.wait()
