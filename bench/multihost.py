"""Two deployments of the service on this machine: one shared folder with SQLite, or S3 and PostgreSQL.

* **A, folder + SQLite**: the default deployment: one storage folder (``HAIRPORT_STORAGE_DIR``) shared by the
  API and the workers, the records and their SQLite index in it;
* **B, S3 + PostgreSQL**: the multi-host deployment of tests/integration/test_multihost.py: blobs in a SeaweedFS
  server (``HAIRPORT_STORAGE_URL=s3://BUCKET/PREFIX``, its endpoint and identity in ``HAIRPORT_S3_*``), records
  in a new database of a PostgreSQL server (``HAIRPORT_DATABASE_URL``), and a storage folder of its own for each
  process (the API and each worker: its cache), so that no folder is shared.

Each starts its own ``redis-server`` (a free port, nothing on disk), one ``hairport serve`` and
:data:`WORKERS` ``hairport worker --concurrency 1 --no-warmup`` processes (kernels from numba's cache); B's
servers are started by the bench with the tests' harness (tests/servers/postgres.py and seaweed.py) and
removed at the end. Inputs are the tests' toy characters (a source and three targets) and procedural grooms,
uploaded through the API and preprocessed before anything is timed; then the bench waits ``--settle`` seconds
(the servers' own start-up work, SeaweedFS growing its volumes above all, shares the two cores with the first
solve otherwise: the first job of B took 14-15 % longer than A's without the wait, 4 % with it; on separate
hosts nothing shares the workers' cores). Then, in each deployment:

1. **one job**: a retarget of a ``--particles`` groom ("long", :data:`PARTICLES_PER_STRAND` particles a
   strand) onto the same target every run, from ``POST /v1/retargets`` to the result downloaded (``GET
   /v1/jobs/{id}/result?format=npz`` read to its end), polling the job every :data:`JOB_POLL_SECONDS`. The
   first run finds every cache empty (the target's collision surface and wrap kept in the storage, what a
   worker keeps in memory and, in B, the worker's folder): it is reported alone (cold), then ``--runs`` more
   (warm; each may run on either worker). Every job must succeed with no penetrating particle;
2. **batch**: ``--runs`` batches of the same :data:`BATCH_HAIRSTYLES` small grooms x :data:`BATCH_TARGETS`
   targets (``options`` :data:`BATCH_OPTIONS`, npz), from ``POST /v1/batches`` to state ``done`` with every
   pair succeeded: pairs per minute;
3. **polls**: ``GET /v1/jobs/{id}`` of the jobs running, ``--pollers`` paced pollers (``--think`` s between an
   answer and the next request, +-50 %, from a random phase; one keep-alive connection each:
   ``service_load.load`` and ``RawConnection``) for ``--seconds``, ``--runs`` windows, while
   ``service_load.feeder`` keeps a retarget of the large groom queued or running on each worker.

Each figure is the median of the runs (min-max beside it). The table compares A and B (B/A), with the issue's
targets: B adds at most :data:`JOB_OVERHEAD_TARGET` to the job, and the paced polls' p99 is at most
:data:`POLL_P99_TARGET_MS`.

    python bench/multihost.py                                       # 10^5 particles, 3 runs, 8 s windows
    python bench/multihost.py --particles 20000 --runs 1 --seconds 3  # a quick check
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import datetime
import os
import platform
import signal
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "bench")]  # tests.servers (the harness) and service_load, beside this script
from service_load import AUTH, KEY, THINK_JITTER, feeder, free_port, load, percentile, wait_until  # noqa: E402

#: worker processes of a deployment (one job each at once)
WORKERS = 2
#: seconds for redis, the API and the workers to answer
START_SECONDS = 120.0
#: seconds one job, one preprocessing or one batch may take before the bench gives up
JOB_SECONDS = 1800.0
#: seconds between two polls of a job or a batch whose end is timed (the resolution of its time)
JOB_POLL_SECONDS = 0.05
#: seconds between the inputs' upload and the first job (``--settle``): the servers' start-up work is over
SETTLE_SECONDS = 30.0
#: seconds between two polls of a preprocessing (not timed)
PREPROCESS_POLL_SECONDS = 0.5
#: seconds a process may take to stop after SIGTERM before it is killed
STOP_SECONDS = 10.0
#: particles per strand of the one-job groom (``--particles`` / this = strands)
PARTICLES_PER_STRAND = 100
#: groom style of the one-job groom and of the small ones
JOB_STYLE, BATCH_STYLE = "long", "short"
#: the batch's grooms: strands x particles each
BATCH_GROOM = (200, 16)
#: hairstyles and targets of the batch
BATCH_HAIRSTYLES, BATCH_TARGETS = 2, 3
#: solver options of the batch's jobs
BATCH_OPTIONS = {"max_iterations": 10}
#: the toy targets (keyword arguments of toy.toy_character); the first is the one-job target
TARGETS = {
    "target": dict(head_scale=(1.1, 0.95, 1.05), neck_length=0.15, shoulder_width=0.42),
    "wide": dict(head_scale=(1.2, 1.0, 1.1), shoulder_width=0.48),
    "slim": dict(head_scale=(0.95, 1.0, 0.95), shoulder_width=0.36),
}
#: the issue's targets: B's job time at most this much over A's (a fraction), the paced polls' p99 (ms)
JOB_OVERHEAD_TARGET = 0.10
POLL_P99_TARGET_MS = 20.0
#: the S3 region B's processes are given (SeaweedFS accepts any)
S3_REGION = "us-east-1"
#: lines of a failing process's log quoted
LOG_TAIL_LINES = 30
DONE = ("succeeded", "failed", "cancelled")


# ---------------------------------------------------------------------- deployments


def fresh_database(server_url: str) -> str:
    """The URL of a new empty database on the server of ``server_url`` (as the tests' ``fresh_database``)."""
    import psycopg

    name = f"bench{uuid.uuid4().hex[:16]}"
    with psycopg.connect(server_url, autocommit=True) as connection:
        connection.execute(f"CREATE DATABASE {name}")
    return server_url.rsplit("/", 1)[0] + f"/{name}"


def s3_settings(seaweed, database_url: str, prefix: str) -> dict:
    """B's shared settings: the bucket's ``prefix`` on the SeaweedFS server, the records in ``database_url``."""
    endpoint, access_key, secret_key, bucket = seaweed.endpoint
    return {"HAIRPORT_STORAGE_URL": f"s3://{bucket}/{prefix}", "HAIRPORT_S3_ENDPOINT_URL": endpoint,
            "HAIRPORT_S3_ACCESS_KEY_ID": access_key, "HAIRPORT_S3_SECRET_ACCESS_KEY": secret_key,
            "HAIRPORT_S3_REGION": S3_REGION, "HAIRPORT_DATABASE_URL": database_url}


class Deployment:
    """redis-server, ``hairport serve`` and :attr:`workers` workers in ``folder``; ``shared`` settings for all.

    With ``shared_folder`` every process has ``folder/storage`` as its storage folder (A); else each has its
    own, ``folder/<name>-cache`` (B). Logs: ``folder/<name>.log``."""

    #: worker processes it starts (each of concurrency 1)
    workers = WORKERS

    def __init__(self, folder: Path, shared: dict, shared_folder: bool):
        self.folder, self.shared_folder, self.processes = folder, shared_folder, {}
        self.redis_port, self.port = free_port(), free_port()
        self.redis_url = f"redis://127.0.0.1:{self.redis_port}/0"
        self.env = {**{k: v for k, v in os.environ.items() if not k.startswith("HAIRPORT_")}, **shared,
                    "HAIRPORT_REDIS_URL": self.redis_url, "HAIRPORT_API_KEYS": KEY, "HAIRPORT_INSECURE_DEV": "false"}

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def storage(self, name: str) -> Path:
        folder = self.folder / ("storage" if self.shared_folder else f"{name}-cache")
        folder.mkdir(exist_ok=True)
        return folder

    def start(self) -> None:
        import httpx

        self._spawn("redis", ["redis-server", "--port", str(self.redis_port), "--bind", "127.0.0.1", "--save", "",
                              "--appendonly", "no", "--dir", str(self.folder)])
        hairport = [sys.executable, "-m", "hairport.cli"]
        self._spawn("api", hairport + ["serve", "--port", str(self.port)])
        wait_until(lambda: self._alive() and httpx.get(f"{self.url}/healthz", timeout=5).status_code == 200,
                   "the API", START_SECONDS)
        names = [f"w{number}" for number in range(1, self.workers + 1)]
        for name in names:
            self._spawn(name, hairport + ["worker", "--concurrency", "1", "--no-warmup", "--hostname", f"{name}@%h",
                                          "--loglevel", "WARNING"])
        wait_until(lambda: self._alive() and len(self.workers_answering()) == self.workers, "the workers",
                   START_SECONDS)
        wait_until(lambda: httpx.get(f"{self.url}/readyz", timeout=5).status_code == 200, "readiness", START_SECONDS)

    def workers_answering(self) -> set[str]:
        from celery import Celery

        app = Celery(broker=self.redis_url)
        try:
            return {name for reply in app.control.ping(timeout=1.0) for name in reply}
        finally:
            app.close()

    def stop(self) -> None:
        """SIGKILL the workers (a running job would hold a warm shutdown), SIGTERM the API and redis."""
        for name, process in reversed(self.processes.items()):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.pid, signal.SIGKILL if name.startswith("w") else signal.SIGTERM)
        for process in self.processes.values():
            try:
                process.wait(timeout=STOP_SECONDS)
            except subprocess.TimeoutExpired:
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(process.pid, signal.SIGKILL)
                process.wait()

    def log_tail(self, name: str) -> str:
        lines = (self.folder / f"{name}.log").read_text(errors="replace").splitlines()
        return "\n".join(lines[-LOG_TAIL_LINES:])

    def failure(self, what: str) -> SystemExit:
        logs = "\n".join(f"--- {name}.log\n{self.log_tail(name)}" for name in self.processes if name != "redis")
        return SystemExit(f"bench: {what}\n{logs}")

    def _alive(self) -> bool:
        dead = [name for name, process in self.processes.items() if process.poll() is not None]
        if dead:
            raise self.failure(f"{', '.join(dead)} exited")
        return True

    def _spawn(self, name: str, command: list[str]) -> None:
        env = self.env if name == "redis" else {**self.env, "HAIRPORT_STORAGE_DIR": str(self.storage(name))}
        with open(self.folder / f"{name}.log", "wb") as log:
            self.processes[name] = subprocess.Popen(command, env=env, stdout=log, stderr=subprocess.STDOUT,
                                                    cwd=self.folder, start_new_session=True)


# ---------------------------------------------------------------------- inputs


def write_inputs(folder: Path, particles: int) -> None:
    """The toy source and targets (``.obj`` + skeleton), the one-job groom and the batch's grooms (``.data``)."""
    from hairport.solver.io.hair import write_hair
    from hairport.solver.synthetic import toy
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import write_character

    source = toy.toy_character(name="source")
    characters = {"source": source, **{name: toy.toy_character(name=name, **shape) for name, shape in TARGETS.items()}}
    for name, character in characters.items():
        write_character(character, folder / f"{name}.obj", folder / f"{name}.skeleton.json")
    write_hair(folder / "job.data", generate_groom(source, JOB_STYLE, max(1, particles // PARTICLES_PER_STRAND),
                                                   PARTICLES_PER_STRAND, seed=0))
    for number in range(BATCH_HAIRSTYLES):
        write_hair(folder / f"batch{number}.data", generate_groom(source, BATCH_STYLE, *BATCH_GROOM, seed=1 + number))


def upload_inputs(client, deployment: Deployment, folder: Path) -> dict:
    """Every input uploaded, the hairstyles preprocessed: ``{"source", target names, "job", "batch": [ids]}``."""
    ids: dict = {}
    for name in ("source", *TARGETS):
        response = client.post("/v1/characters", files={
            "mesh": (f"{name}.obj", (folder / f"{name}.obj").read_bytes()),
            "skeleton": (f"{name}.skeleton.json", (folder / f"{name}.skeleton.json").read_bytes())})
        response.raise_for_status()
        ids[name] = response.json()["id"]
    hairstyles = {}
    for name in ("job", *(f"batch{number}" for number in range(BATCH_HAIRSTYLES))):
        response = client.post("/v1/hairstyles", data={"source_character_id": ids["source"]},
                               files={"hair": (f"{name}.data", (folder / f"{name}.data").read_bytes())})
        response.raise_for_status()
        hairstyles[name] = response.json()["id"]
    for name, hairstyle in hairstyles.items():
        wait_until(lambda: preprocessed(client, deployment, hairstyle), f"the preprocessing of {name}", JOB_SECONDS)
    ids["job"] = hairstyles["job"]
    ids["batch"] = [hairstyles[f"batch{number}"] for number in range(BATCH_HAIRSTYLES)]
    return ids


def preprocessed(client, deployment: Deployment, hairstyle: str) -> bool:
    state = client.get(f"/v1/hairstyles/{hairstyle}").json()["preprocessing"]["state"]
    if state == "failed":
        raise deployment.failure(f"the preprocessing of hairstyle {hairstyle} failed")
    if state != "ready":
        time.sleep(PREPROCESS_POLL_SECONDS)
    return state == "ready"


# ---------------------------------------------------------------------- measurements


def wait_for(client, path: str, done, deployment: Deployment, what: str) -> dict:
    """GET ``path`` every :data:`JOB_POLL_SECONDS` until ``done(body)``; the body."""
    deadline = time.monotonic() + JOB_SECONDS
    while True:
        body = client.get(path).json()
        if done(body):
            return body
        if time.monotonic() > deadline:
            raise deployment.failure(f"{what} did not end within {JOB_SECONDS:g} s: {body}")
        time.sleep(JOB_POLL_SECONDS)


def one_job(client, deployment: Deployment, ids: dict) -> dict:
    """One retarget of the large groom onto the first target, from submit to the result downloaded: seconds
    (wall, queued, running in the worker, from the end to the last byte), the worker, timings and metrics."""
    submitted, began = time.time(), time.perf_counter()
    response = client.post("/v1/retargets", json={"hairstyle_id": ids["job"], "target_character_ids": [ids["target"]],
                                                   "output_format": "npz"})
    response.raise_for_status()
    job_id = response.json()["jobs"][0]["id"]
    job = wait_for(client, f"/v1/jobs/{job_id}", lambda body: body["state"] in DONE, deployment, f"job {job_id}")
    if job["state"] != "succeeded":
        raise deployment.failure(f"job {job_id} {job['state']}: {job.get('error')}")
    ended = time.perf_counter()
    size = 0
    with client.stream("GET", f"/v1/jobs/{job_id}/result", params={"format": "npz"}) as result:
        result.raise_for_status()
        for chunk in result.iter_bytes():
            size += len(chunk)
    wall = time.perf_counter() - began
    return {"wall": wall, "queued": job["started_at"] - submitted, "running": job["finished_at"] - job["started_at"],
            "download": time.perf_counter() - ended, "bytes": size, "worker": job["worker"].split("@")[0],
            "timings": job["timings"] or {}, "penetrating": (job["metrics"] or {}).get("penetrating_particles")}


def one_batch(client, deployment: Deployment, ids: dict) -> dict:
    """The batch from submit to ``done``: seconds, pairs per minute, the workers that ran its jobs."""
    targets = list(TARGETS)[:BATCH_TARGETS]
    began = time.perf_counter()
    response = client.post("/v1/batches", json={"hairstyle_ids": ids["batch"],
                                                "target_character_ids": [ids[name] for name in targets],
                                                "options": BATCH_OPTIONS, "output_format": "npz"})
    response.raise_for_status()
    batch_id = response.json()["id"]
    done = wait_for(client, f"/v1/batches/{batch_id}", lambda body: body["state"] == "done", deployment,
                    f"batch {batch_id}")
    seconds = time.perf_counter() - began
    pairs = BATCH_HAIRSTYLES * BATCH_TARGETS
    if done["counts"]["succeeded"] != pairs:
        raise deployment.failure(f"batch {batch_id}: {done['counts']}")
    jobs = [client.get(f"/v1/jobs/{job['id']}").json() for job in done["jobs"]]
    return {"seconds": seconds, "rate": 60.0 * pairs / seconds,
            "beyond": statistics.median(beyond_solve(job["timings"] or {}) for job in jobs),
            "workers": sorted({job["worker"].split("@")[0] for job in jobs})}


def beyond_solve(timings: dict) -> float:
    """Seconds of a job's run in the worker beyond its solve: loading its inputs, the target's cache, checks,
    metrics and writing its outputs (where the storage's own time is)."""
    return timings.get("job", float("nan")) - timings.get("solve", 0.0)


async def poll_windows(url: str, ids: dict, args) -> list[dict]:
    """``args.runs`` windows of paced pollers of the running jobs, a retarget kept running on each worker."""
    import httpx

    limits = httpx.Limits(max_connections=8, max_keepalive_connections=8)
    windows = []
    async with httpx.AsyncClient(base_url=url, headers=AUTH, timeout=60, limits=limits) as client:
        jobs: list[str] = []
        busy: list[float] = []
        stop = asyncio.Event()
        feed = asyncio.create_task(feeder(client, {"hairstyle": ids["job"], "target": ids["target"]}, jobs, busy,
                                          stop))
        try:
            deadline = time.monotonic() + START_SECONDS
            while not busy:
                if feed.done():
                    feed.result()
                if time.monotonic() > deadline:
                    raise SystemExit("bench: no retarget job started running")
                await asyncio.sleep(0.2)
            for _ in range(args.runs):
                paths = [f"/v1/jobs/{job_id}" for job_id in jobs[-WORKERS:]]
                began = time.monotonic()
                latencies, errors = await load(client, paths, args.pollers, args.seconds, args.think, url)
                windows.append({"p50": percentile(latencies, 50), "p99": percentile(latencies, 99),
                                "rate": len(latencies) / args.seconds, "errors": errors,
                                "running": any(began <= moment for moment in busy[-3:])})
        finally:
            stop.set()
            await feed
    return windows


def measure(deployment: Deployment, inputs: Path, args) -> dict:
    """Every measurement of one started deployment."""
    import httpx

    with httpx.Client(base_url=deployment.url, headers=AUTH, timeout=600) as client:
        began = time.perf_counter()
        ids = upload_inputs(client, deployment, inputs)
        print(f"  inputs uploaded and preprocessed in {time.perf_counter() - began:.1f} s", flush=True)
        time.sleep(args.settle)
        jobs = []
        for number in range(args.runs + 1):
            jobs.append(one_job(client, deployment, ids))
            print(f"  job {number + 1} ({'cold' if number == 0 else 'warm'}): {describe_job(jobs[-1])}", flush=True)
        batches = []
        for number in range(args.runs):
            batches.append(one_batch(client, deployment, ids))
            print(f"  batch {number + 1}: {batches[-1]['seconds']:.1f} s, {batches[-1]['rate']:.1f} pairs/min, on "
                  f"{', '.join(batches[-1]['workers'])}; a job's run beyond its solve {batches[-1]['beyond']:.2f} s "
                  "(median)", flush=True)
    polls = asyncio.run(poll_windows(deployment.url, ids, args))
    for number, window in enumerate(polls):
        print(f"  polls {number + 1}: p50 {window['p50']:.1f} ms, p99 {window['p99']:.1f} ms, "
              f"{window['rate']:.0f} req/s, {window['errors']} errors, job running: {window['running']}", flush=True)
    return {"jobs": jobs, "batches": batches, "polls": polls}


def describe_job(job: dict) -> str:
    stages = ", ".join(f"{name} {seconds:.2f}" for name, seconds in job["timings"].items()
                       if isinstance(seconds, (int, float)))
    return (f"{job['wall']:.2f} s on {job['worker']} (submit -> started {job['queued']:.2f}, running "
            f"{job['running']:.2f}, "
            f"result {job['bytes'] / 1e6:.1f} MB in {job['download']:.2f}); penetrating {job['penetrating']}; "
            f"timings: {stages}")


def run_a(inputs: Path, args) -> dict:
    with tempfile.TemporaryDirectory(prefix="hairport-bench-multihost-a-") as temp:
        deployment = Deployment(Path(temp), {}, shared_folder=True)
        try:
            deployment.start()
            return measure(deployment, inputs, args)
        finally:
            deployment.stop()


def run_b(inputs: Path, args) -> dict:
    from tests.servers.postgres import PostgresServer
    from tests.servers.seaweed import SeaweedServer

    with PostgresServer() as postgres, SeaweedServer() as seaweed, \
            tempfile.TemporaryDirectory(prefix="hairport-bench-multihost-b-") as temp:
        shared = s3_settings(seaweed, fresh_database(postgres.url), f"bench-{uuid.uuid4().hex[:8]}")
        deployment = Deployment(Path(temp), shared, shared_folder=False)
        try:
            deployment.start()
            return measure(deployment, inputs, args)
        finally:
            deployment.stop()


# ---------------------------------------------------------------------- the table


def spread(values: list[float], digits: int) -> str:
    """``median (min-max)``, or the one value."""
    if len(values) == 1:
        return f"{values[0]:.{digits}f}"
    return f"{statistics.median(values):.{digits}f} ({min(values):.{digits}f}-{max(values):.{digits}f})"


def rows(result: dict) -> dict[str, tuple[list[float], int]]:
    """Each measurement's values (one a run) and its digits."""
    cold, warm = result["jobs"][0], result["jobs"][1:]
    return {
        "job, cold (first run) s": ([cold["wall"]], 2),
        "job, warm s": ([job["wall"] for job in warm], 2),
        "job, warm: running in the worker s": ([job["running"] for job in warm], 2),
        "job, warm: in the worker beyond the solve s": ([beyond_solve(job["timings"]) for job in warm], 2),
        "job, warm: submit -> started s": ([job["queued"] for job in warm], 2),
        "job, warm: result download s": ([job["download"] for job in warm], 3),
        "batch s": ([batch["seconds"] for batch in result["batches"]], 1),
        "batch pairs/min": ([batch["rate"] for batch in result["batches"]], 1),
        "batch: a job's run beyond its solve s": ([batch["beyond"] for batch in result["batches"]], 2),
        "poll p50 ms": ([window["p50"] for window in result["polls"]], 1),
        "poll p99 ms": ([window["p99"] for window in result["polls"]], 1),
        "poll req/s": ([window["rate"] for window in result["polls"]], 0),
    }


def table(results: dict[str, dict], args) -> str:
    a, b = (rows(result) for result in results.values())
    lines = [f"hairport multi-host - {datetime.date.today()} - {platform.node()} ({os.cpu_count()} cores, "
             f"{platform.processor() or platform.machine()}, Python {platform.python_version()}) - load average "
             f"at the end {os.getloadavg()[0]:.1f} (other work on the machine counts)",
             "A: one storage folder, records and index in it (SQLite); B: blobs in SeaweedFS "
             f"(S3), records in PostgreSQL, a cache folder per process; each: redis, one API, {WORKERS} workers "
             "(concurrency 1)",
             f"job: {args.particles:,} particles ({args.particles // PARTICLES_PER_STRAND:,} strands x "
             f"{PARTICLES_PER_STRAND}, '{JOB_STYLE}'), the same target every run, submit -> npz result read; cold: "
             f"the first job, warm: median (min-max) of {args.runs}; batch: {BATCH_HAIRSTYLES} x {BATCH_TARGETS} of "
             f"{BATCH_GROOM[0]} x {BATCH_GROOM[1]} particles, {BATCH_OPTIONS}, median of {args.runs}; polls: "
             f"{args.pollers} paced pollers ({args.think:g} s think +-{THINK_JITTER:.0%}, random phase) of the jobs "
             f"running (a retarget of the job's groom on each worker), {args.seconds:g} s windows, median of "
             f"{args.runs}",
             "", "| measurement | A: folder + SQLite | B: S3 + PostgreSQL | B/A |", "|---|---:|---:|---:|"]
    for name, (values, digits) in a.items():
        other = b[name][0]
        ratio = statistics.median(other) / statistics.median(values) if statistics.median(values) else float("nan")
        lines.append(f"| {name} | {spread(values, digits)} | {spread(other, digits)} | {ratio:.2f} |")
    lines += ["", *checks(results)]
    return "\n".join(lines)


def checks(results: dict[str, dict]) -> list[str]:
    """The issue's targets, and the jobs' correctness, met or not."""
    a, b = results.values()
    lines = []
    for row, kind in (("job, cold (first run) s", "cold, one run"), ("job, warm s", "warm")):
        ratio = statistics.median(rows(b)[row][0]) / statistics.median(rows(a)[row][0])
        lines.append(f"- B adds at most {JOB_OVERHEAD_TARGET:.0%} to the job ({kind}): B/A = {ratio:.2f}: "
                     f"{'met' if ratio <= 1 + JOB_OVERHEAD_TARGET else 'NOT met'}")
    for name, result in results.items():
        p99 = statistics.median(window["p99"] for window in result["polls"])
        errors = sum(window["errors"] for window in result["polls"])
        running = all(window["running"] for window in result["polls"])
        lines.append(f"- {name}: paced poll p99 {p99:.1f} ms <= {POLL_P99_TARGET_MS:g} ms: "
                     f"{'met' if p99 <= POLL_P99_TARGET_MS else 'NOT met'} ({errors} errors; a job running in every "
                     f"window: {'yes' if running else 'no'})")
        penetrating = [job["penetrating"] for job in result["jobs"]]
        lines.append(f"- {name}: every job succeeded, penetrating particles {penetrating}: "
                     f"{'ok' if all(count == 0 for count in penetrating) else 'NOT ok'}")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--particles", type=int, default=100_000, help="particles of the one-job groom")
    parser.add_argument("--runs", type=int, default=3, help="runs of every measurement (the median is reported)")
    parser.add_argument("--seconds", type=float, default=8.0, help="length of one polling window")
    parser.add_argument("--pollers", type=int, default=100, help="concurrent paced pollers of GET /v1/jobs/{id}")
    parser.add_argument("--think", type=float, default=0.5, help="seconds a poller waits between polls")
    parser.add_argument("--settle", type=float, default=SETTLE_SECONDS,
                        help="seconds to wait after the inputs' upload, before the first job")
    args = parser.parse_args(argv)
    # a SIGTERM ends the bench as Ctrl-C does: every server and process stopped, every folder removed
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(128 + signal.SIGTERM))
    results = {}
    with tempfile.TemporaryDirectory(prefix="hairport-bench-multihost-inputs-") as folder:
        write_inputs(Path(folder), args.particles)
        for name, run in (("A: folder + SQLite", run_a), ("B: S3 + PostgreSQL", run_b)):
            began = time.perf_counter()
            print(f"measuring {name} ...", flush=True)
            results[name] = run(Path(folder), args)
            print(f"  {name} measured in {time.perf_counter() - began:.0f} s", flush=True)
    print(table(results, args))
    return 0


if __name__ == "__main__":
    sys.exit(main())
