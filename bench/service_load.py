"""Service read latency under load: job polls while jobs run, listings and /metrics with 10^4 jobs kept.

Starts its own ``redis-server`` (a free port, nothing on disk), a real ``hairport serve`` and one
real ``hairport worker`` on a temporary storage folder, stores ``--records`` job records (written
directly through the Repository, as the API would write them, so that 10^4 jobs take seconds, not
hours of solving), uploads the toy characters and a procedural groom of the tests through the API,
and keeps the worker busy with real retarget jobs (a new one is submitted whenever fewer than two
are queued or running) while it measures:

* ``GET /v1/jobs/{id}``: ``--pollers`` concurrent pollers (asyncio + httpx, one connection each),
  two load models: *closed loop* (each poller sends its next request as soon as the last one
  answered: the server's saturation, latency ~ pollers / throughput) and *paced* (each poller waits
  about ``--think`` seconds (+-50 %, from a random phase) between the answer and its next request, as
  independent clients polling a job do);
* ``GET /v1/jobs?limit=50``, ``GET /v1/jobs?state=succeeded&limit=50`` and ``GET /metrics`` with
  the records kept: ``--list-clients`` closed-loop clients each; the page of 50 also with one client
  and with ``--list-clients`` paced at ``--list-think`` seconds (dashboards refreshing);
* uploads (after the windows above): the paced polls while two hair files of 10^6 two-point strands
  (28 MB ``.data`` each, as a load probe sent) are uploaded at once and validated, from their first
  byte sent to the last answer; and the peak resident memory of the API process, alone and with its
  child processes (the validation pool's), sampled every :data:`SAMPLE_SECONDS` while
  :data:`MEMORY_UPLOADS` hair files of 5 MB are uploaded at once. Every upload is new content (the
  same groom with one coordinate moved by a few ulps), so that each one is validated.

Every window runs ``--seconds`` seconds; each figure is the median over ``--runs`` runs. With
``--baseline-ref REV`` the same measurements run first against the code of that git revision (its
files exported into a temporary folder and put first on ``PYTHONPATH``), so old and new are
measured in the same session on the same machine.

    python bench/service_load.py                       # this tree
    python bench/service_load.py --baseline-ref ad5d7e2 --serve-workers 2
"""

from __future__ import annotations

import argparse
import asyncio
import collections
import contextlib
import datetime
import json
import os
import platform
import random
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
KEY = "bench-key"
AUTH = {"Authorization": f"Bearer {KEY}"}
#: seconds to wait for redis, the API and the worker to answer
START_SECONDS = 60.0
#: jobs kept queued or running by the feeder, so that the worker never idles during a window
BUSY_JOBS = 2
#: groom of the retarget jobs: strands x particles (a job of a few seconds on one core)
GROOM = (400, 16)
#: a paced client's think time varies by this fraction either way (uniformly)
THINK_JITTER = 0.5
#: seconds between the feeder's checks
FEED_SECONDS = 0.5
#: strands (of two points each) of the upload windows' grooms: a 28 MB and a 5 MB ``.data`` file
LARGE_UPLOAD_STRANDS = 1_000_000
SMALL_UPLOAD_STRANDS = 180_000
#: large uploads validated while the pollers poll
LARGE_UPLOADS = 2
#: uploads at once in the memory window
MEMORY_UPLOADS = 50
#: seconds between samples of the API's resident memory
SAMPLE_SECONDS = 0.02
#: seconds an upload may take (the code before the validation pool validated fifty 5 MB files in one
#: process, one after the other in effect)
UPLOAD_TIMEOUT_SECONDS = 900


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def wait_until(check, what: str, seconds: float = START_SECONDS) -> None:
    deadline = time.monotonic() + seconds
    while True:
        with contextlib.suppress(Exception):
            if check():
                return
        if time.monotonic() > deadline:
            raise SystemExit(f"bench: {what} did not start")
        time.sleep(0.1)


# ---------------------------------------------------------------------- the code under test


def source_tree(ref: str | None, folder: Path) -> dict:
    """Environment additions running the code of ``ref`` (None: the installed tree)."""
    if ref is None:
        return {}
    export = folder / "export"
    export.mkdir()
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", ref], check=True, capture_output=True).stdout
    subprocess.run(["tar", "-x", "-C", str(export)], input=archive, check=True)
    # the installed layout: solver/, service/ and worker/ are subpackages of hairport
    package = folder / "site" / "hairport"
    shutil.copytree(export / "hairport", package)
    for sub in ("solver", "service", "worker"):
        shutil.copytree(export / sub, package / sub)
    return {"PYTHONPATH": str(folder / "site")}


def populate(storage: str, records: int, owner: str) -> None:
    """Store ``records`` job records of ``owner`` (run in a subprocess under the code being measured)."""
    import random

    from hairport.records import JOB_STATES, JobRecord, PreprocessSettings, now
    from hairport.repository import Repository
    from hairport.storage import LocalStorage

    repository = Repository(LocalStorage(Path(storage), durable=False))
    rng = random.Random(0)
    moment = now() - records
    for number in range(records):
        state = rng.choice(JOB_STATES)
        timings = {"job": 3.0, "solve": 2.0} if state == "succeeded" else None
        repository.create_job(JobRecord(
            id=f"{number:032x}", owner=owner, state=state, hairstyle_id="0" * 32, target_character_id="0" * 32,
            options={}, preprocess_options=PreprocessSettings(k=5, guides=20), artifact_key="0" * 64,
            output_format="data", created_at=moment + number, updated_at=moment + number, timings=timings))


class Service:
    """redis-server, ``hairport serve`` and ``hairport worker`` on a temporary storage."""

    def __init__(self, folder: Path, extra_env: dict, serve_args: list[str]):
        self.folder, self.processes = folder, []
        self.storage = folder / "storage"
        self.storage.mkdir()
        redis_port, self.port = free_port(), free_port()
        self.env = {**os.environ, **extra_env, "HAIRPORT_REDIS_URL": f"redis://127.0.0.1:{redis_port}/0",
                    "HAIRPORT_STORAGE_DIR": str(self.storage), "HAIRPORT_API_KEYS": KEY,
                    "HAIRPORT_INSECURE_DEV": "false"}
        self.redis_port = redis_port
        self.serve_args = serve_args

    def start_redis(self) -> None:
        import redis

        self._spawn("redis", ["redis-server", "--port", str(self.redis_port), "--bind", "127.0.0.1", "--save", "",
                              "--appendonly", "no", "--dir", str(self.folder)])
        client = redis.Redis(port=self.redis_port)
        wait_until(client.ping, "redis-server")

    def start_api_and_worker(self) -> None:
        import httpx

        hairport = [sys.executable, "-m", "hairport.cli"]
        self.serve = self._spawn("serve", hairport + ["serve", "--port", str(self.port), *self.serve_args])
        self._spawn("worker", hairport + ["worker", "--concurrency", "1", "--loglevel", "WARNING"])
        wait_until(lambda: httpx.get(f"{self.url}/readyz", timeout=5).status_code == 200, "the API and the worker")

    def run_python(self, *args: str) -> None:
        subprocess.run([sys.executable, *args], env=self.env, check=True, cwd=self.folder)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def _spawn(self, name: str, command: list[str]) -> subprocess.Popen:
        log = open(self.folder / f"{name}.log", "wb")
        self.processes.append(subprocess.Popen(command, env=self.env, stdout=log, stderr=subprocess.STDOUT,
                                               cwd=self.folder, start_new_session=True))
        return self.processes[-1]

    def stop(self) -> None:
        for process in reversed(self.processes):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.pid, 15)
        for process in self.processes:
            try:
                process.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, 9)


# ---------------------------------------------------------------------- inputs and the feeder


def upload_inputs(url: str, folder: Path) -> dict:
    """The toy characters and a procedural groom of the tests, uploaded; ids."""
    import httpx

    from hairport.solver.io.hair import write_hair
    from hairport.solver.synthetic import toy
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import write_character

    source = toy.toy_character(name="source")
    target = toy.toy_character(head_scale=(1.1, 0.95, 1.05), neck_length=0.15, shoulder_width=0.42, name="target")
    ids = {}
    with httpx.Client(base_url=url, headers=AUTH, timeout=120) as client:
        for name, character in (("source", source), ("target", target)):
            write_character(character, folder / f"{name}.obj", folder / f"{name}.skeleton.json")
            response = client.post("/v1/characters", files={
                "mesh": (f"{name}.obj", (folder / f"{name}.obj").read_bytes()),
                "skeleton": (f"{name}.skeleton.json", (folder / f"{name}.skeleton.json").read_bytes())})
            response.raise_for_status()
            ids[name] = response.json()["id"]
        write_hair(folder / "hair.data", generate_groom(source, "short", *GROOM, seed=0))
        response = client.post("/v1/hairstyles", data={"source_character_id": ids["source"], "guides": "20"},
                               files={"hair": ("groom.data", (folder / "hair.data").read_bytes())})
        response.raise_for_status()
        ids["hairstyle"] = response.json()["id"]
    return ids


async def feeder(client, ids: dict, jobs: list[str], busy: list[float], stop: asyncio.Event) -> None:
    """Keep BUSY_JOBS retargets queued or running; record when a job was seen running."""
    request = {"hairstyle_id": ids["hairstyle"], "target_character_ids": [ids["target"]]}
    pending: list[str] = []
    while not stop.is_set():
        states = []
        for job_id in pending:
            states.append((job_id, (await client.get(f"/v1/jobs/{job_id}")).json()["state"]))
        pending = [job_id for job_id, state in states if state in ("queued", "running")]
        if any(state == "running" for _, state in states):
            busy.append(time.monotonic())
        if any(state == "failed" for _, state in states):
            raise SystemExit("bench: a retarget job failed (see the worker log)")
        while len(pending) < BUSY_JOBS:
            response = await client.post("/v1/retargets", json=request)
            response.raise_for_status()
            pending.append(response.json()["jobs"][0]["id"])
            jobs.append(pending[-1])
        with contextlib.suppress(asyncio.TimeoutError):
            await asyncio.wait_for(stop.wait(), FEED_SECONDS)


# ---------------------------------------------------------------------- load


class RawConnection:
    """A minimal HTTP/1.1 keep-alive client on asyncio streams (GET only, Content-Length bodies).

    httpx costs 1-3 ms of CPU per request at 100 concurrent connections on a 2-core machine, more
    than the server does; sharing the cores with the server, it would measure itself. This client
    costs a few tens of microseconds (``--client httpx`` measures with httpx instead)."""

    def __init__(self, url: str):
        self.host, _, port = url.removeprefix("http://").partition(":")
        self.port = int(port)
        self.reader = self.writer = None
        self.headers = "".join(f"{name}: {value}\r\n" for name, value in AUTH.items())

    async def get(self, path: str) -> int:
        if self.writer is None:
            self.reader, self.writer = await asyncio.open_connection(self.host, self.port)
        self.writer.write(f"GET {path} HTTP/1.1\r\nHost: {self.host}\r\n{self.headers}\r\n".encode())
        head = await self.reader.readuntil(b"\r\n\r\n")
        lines = head.decode("latin-1").split("\r\n")
        length = next(int(line.split(":", 1)[1]) for line in lines if line.lower().startswith("content-length:"))
        await self.reader.readexactly(length)
        return int(lines[0].split()[1])

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()


async def load(client, paths: list[str], clients: int, seconds: float, think: float,
               raw_url: str | None = None, until: asyncio.Event | None = None) -> tuple[list[float], int]:
    """``clients`` loops sending GETs of ``paths`` (round robin) for ``seconds`` (or until ``until`` is set);
    latencies (ms), errors. With ``raw_url`` each loop has its own :class:`RawConnection`, else they share
    the httpx ``client``."""
    latencies: list[float] = []
    errors = 0
    end = time.monotonic() + seconds

    async def loop(offset: int) -> None:
        nonlocal errors
        turn = offset
        connection = RawConnection(raw_url) if raw_url else None
        # independent clients: paced ones start at a random phase of their period and vary it by
        # THINK_JITTER, else they stay in step and arrive as one burst of `clients` requests
        pace = random.Random(offset)
        try:
            if think:
                await asyncio.sleep(pace.uniform(0.0, think))
            while time.monotonic() < end and not (until is not None and until.is_set()):
                began = time.perf_counter()
                if connection is not None:
                    status = await connection.get(paths[turn % len(paths)])
                else:
                    status = (await client.get(paths[turn % len(paths)])).status_code
                latencies.append((time.perf_counter() - began) * 1000.0)
                errors += status != 200
                turn += 1
                if think and until is not None:
                    with contextlib.suppress(asyncio.TimeoutError):
                        await asyncio.wait_for(until.wait(), think * pace.uniform(1.0 - THINK_JITTER,
                                                                                  1.0 + THINK_JITTER))
                elif think:
                    await asyncio.sleep(think * pace.uniform(1.0 - THINK_JITTER, 1.0 + THINK_JITTER))
        finally:
            if connection is not None:
                connection.close()

    await asyncio.gather(*(loop(i) for i in range(clients)))
    return latencies, errors


# ---------------------------------------------------------------------- uploads


def upload_grooms(folder: Path) -> dict[str, bytes]:
    """The ``.data`` files of the upload windows (grooms of two-point strands on the source toy), as bytes."""
    from hairport.solver.io.hair import write_hair
    from hairport.solver.synthetic import toy
    from hairport.solver.synthetic.groom import generate_groom

    source = toy.toy_character(name="source")
    grooms = {}
    for name, strands in (("large", LARGE_UPLOAD_STRANDS), ("small", SMALL_UPLOAD_STRANDS)):
        write_hair(folder / f"{name}.data", generate_groom(source, "short", strands, 2, seed=1))
        grooms[name] = (folder / f"{name}.data").read_bytes()
    return grooms


def variant(data: bytes, number: int) -> bytes:
    """``data`` (a ``.data`` file) with its last coordinate moved by ``number`` ulps: new content, the same groom."""
    last = int.from_bytes(data[-4:], "little", signed=True)
    return data[:-4] + (last + number).to_bytes(4, "little", signed=True)


def resident_bytes(pid: int) -> tuple[int, int]:
    """Resident memory of process ``pid``, and of it with every process it started (its validation children)."""
    parents, rss = {}, {}
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        with contextlib.suppress(OSError, ValueError, IndexError):
            with open(f"/proc/{entry.name}/stat") as stat:
                fields = stat.read().rpartition(")")[2].split()
            parents[int(entry.name)] = int(fields[1])
            rss[int(entry.name)] = int(fields[21]) * os.sysconf("SC_PAGE_SIZE")
    tree, frontier = {pid}, [pid]
    while frontier:
        frontier = [child for child, parent in parents.items() if parent in frontier and child not in tree]
        tree.update(frontier)
    return rss.get(pid, 0), sum(rss.get(member, 0) for member in tree)


def upload_main(url: str, source_id: str, paths: list[str]) -> int:
    """``service_load.py upload URL SOURCE_ID PATH...``: POST every hair file at once as a hairstyle of the
    source, one connection and thread each; prints ``sending``, then the statuses (JSON). A process of its
    own, so that sending them takes nothing from the pollers' process."""
    import concurrent.futures

    import httpx

    def upload(path: str) -> int:
        with httpx.Client(base_url=url, headers=AUTH, timeout=UPLOAD_TIMEOUT_SECONDS) as client:
            return client.post("/v1/hairstyles", data={"source_character_id": source_id},
                               files={"hair": (Path(path).name, Path(path).read_bytes())}).status_code

    print("sending", flush=True)
    with concurrent.futures.ThreadPoolExecutor(len(paths)) as threads:
        print(json.dumps(list(threads.map(upload, paths))), flush=True)
    return 0


class Uploads:
    """Variants of a groom (files in ``folder``) uploaded at once by an uploader process (:func:`upload_main`).

    ``await Uploads(...).start()`` returns once the uploads are being sent; :attr:`done` is set, and
    :attr:`statuses` filled, when the last one is answered."""

    def __init__(self, url: str, source_id: str, folder: Path, groom: bytes, first: int, count: int):
        self.url, self.source_id, self.done = url, source_id, asyncio.Event()
        self.paths = [folder / f"upload-{first + number}.data" for number in range(count)]
        for number, path in enumerate(self.paths):
            path.write_bytes(variant(groom, first + number))
        self.statuses: list[int] = []

    async def start(self) -> Uploads:
        self.process = await asyncio.create_subprocess_exec(
            sys.executable, str(Path(__file__).resolve()), "upload", self.url, self.source_id, *map(str, self.paths),
            stdout=asyncio.subprocess.PIPE)
        if (await self.process.stdout.readline()).strip() != b"sending":
            raise SystemExit("bench: the uploader did not start")
        self.finished = asyncio.create_task(self._finish())
        return self

    async def _finish(self) -> None:
        output, _ = await self.process.communicate()
        self.statuses = json.loads(output)
        self.done.set()
        for path in self.paths:
            path.unlink()


async def poll_while_uploading(client, url: str, ids: dict, paths: list[str], uploads: Uploads,
                               args) -> tuple[list[float], int]:
    """Paced pollers of ``paths`` from the start of ``uploads`` to their last answer; latencies (ms), errors."""
    await uploads.start()
    latencies, errors = await load(client, paths, args.pollers, UPLOAD_TIMEOUT_SECONDS, args.think,
                                   url if args.client == "raw" else None, until=uploads.done)
    await uploads.finished
    return latencies, errors


async def memory_under_uploads(api_pid: int, uploads: Uploads) -> tuple[int, int, int]:
    """Resident bytes of the API process before ``uploads``, its peak while they run, and the peak of it with
    its children."""
    before, _ = resident_bytes(api_pid)
    peak = [before, 0]
    await uploads.start()
    while not uploads.done.is_set():
        api, tree = await asyncio.to_thread(resident_bytes, api_pid)
        peak = [max(peak[0], api), max(peak[1], tree)]
        with contextlib.suppress(asyncio.TimeoutError):
            await asyncio.wait_for(uploads.done.wait(), SAMPLE_SECONDS)
    await uploads.finished
    return before, peak[0], peak[1]


def percentile(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(round(q / 100.0 * (len(ordered) - 1))))] if ordered else float("nan")


async def measure(url: str, ids: dict, args, api_pid: int, grooms: dict[str, bytes],
                  folder: Path) -> tuple[dict, list]:
    """Every window, ``args.runs`` times: ``{name: [(p50, p99, requests per second, errors), ...]}``; the
    memory under uploads, once a run."""
    import httpx

    limits = httpx.Limits(max_connections=args.pollers + args.list_clients + 4,
                          max_keepalive_connections=args.pollers + args.list_clients + 4)
    results: dict[str, list] = {}
    # the feeder waits as long as an upload may: the code before the validation pool answered nothing while
    # it validated fifty uploads
    async with httpx.AsyncClient(base_url=url, headers=AUTH, timeout=UPLOAD_TIMEOUT_SECONDS, limits=limits) as client:
        jobs: list[str] = []
        busy: list[float] = []
        stop = asyncio.Event()
        feed = asyncio.create_task(feeder(client, ids, jobs, busy, stop))
        deadline = time.monotonic() + START_SECONDS * 4
        while not busy:  # the first job running (after the hairstyle's preprocessing)
            if feed.done():
                feed.result()
            if time.monotonic() > deadline:
                raise SystemExit("bench: no retarget job started running")
            await asyncio.sleep(0.2)
        windows = {
            "poll, closed loop": ("poll", args.pollers, 0.0),
            f"poll, {args.think:g} s think": ("poll", args.pollers, args.think),
            "list 50, one client": (["/v1/jobs?limit=50"], 1, 0.0),
            f"list 50, {args.list_think:g} s think": (["/v1/jobs?limit=50"], args.list_clients, args.list_think),
            "list 50": (["/v1/jobs?limit=50"], args.list_clients, 0.0),
            "list 50, state": (["/v1/jobs?state=succeeded&limit=50"], args.list_clients, 0.0),
            "metrics": (["/metrics"], args.list_clients, 0.0),
        }
        for _ in range(args.runs):
            for name, (paths, clients, think) in windows.items():
                if paths == "poll":
                    paths = [f"/v1/jobs/{job_id}" for job_id in jobs[-BUSY_JOBS:]]
                began = time.monotonic()
                latencies, errors = await load(client, paths, clients, args.seconds, think,
                                               url if args.client == "raw" else None)
                ran = any(began <= moment for moment in busy[-3:])
                results.setdefault(name, []).append((percentile(latencies, 50), percentile(latencies, 99),
                                                     len(latencies) / args.seconds, errors, ran))
        memory = []
        uploading = f"poll, {args.think:g} s think, while {LARGE_UPLOADS} uploads of 28 MB validate"
        for number in range(args.runs):
            paths = [f"/v1/jobs/{job_id}" for job_id in jobs[-BUSY_JOBS:]]
            large = Uploads(url, ids["source"], folder, grooms["large"], 1 + number * LARGE_UPLOADS, LARGE_UPLOADS)
            began = time.monotonic()
            latencies, errors = await poll_while_uploading(client, url, ids, paths, large, args)
            seconds = time.monotonic() - began
            results.setdefault(uploading, []).append((percentile(latencies, 50), percentile(latencies, 99),
                                                      len(latencies) / seconds, errors,
                                                      any(began <= moment for moment in busy[-3:])))
            small = Uploads(url, ids["source"], folder, grooms["small"], 1 + number * MEMORY_UPLOADS, MEMORY_UPLOADS)
            memory.append((*await memory_under_uploads(api_pid, small), small.statuses, large.statuses, seconds))
        stop.set()
        await feed
    return results, memory


def run(ref: str | None, args, grooms: dict[str, bytes]) -> tuple[dict, list]:
    with tempfile.TemporaryDirectory(prefix="hairport-bench-") as temp:
        folder = Path(temp)
        service = Service(folder, source_tree(ref, folder), [] if ref else args.serve_args)
        try:
            service.start_redis()
            began = time.perf_counter()
            from hairport.service.auth import owner_of

            service.run_python(str(Path(__file__).resolve()), "populate", str(service.storage), str(args.records),
                               owner_of(KEY))
            print(f"  {args.records} job records stored in {time.perf_counter() - began:.1f} s", flush=True)
            service.start_api_and_worker()
            ids = upload_inputs(service.url, folder)
            return asyncio.run(measure(service.url, ids, args, service.serve.pid, grooms, folder))
        finally:
            service.stop()


def table(results: dict[str, dict], memory: dict[str, list], args) -> str:
    lines = [f"hairport service load - {datetime.date.today()} - {platform.node()} ({os.cpu_count()} cores, "
             f"{platform.processor() or platform.machine()}, Python {platform.python_version()})",
             f"load: {args.pollers} pollers on the jobs being run (closed loop, and paced: {args.think:g} s think time "
             f"+-{THINK_JITTER:.0%}, random phase); listings and /metrics: {args.list_clients} closed-loop clients "
             f"(also one client, and {args.list_clients} paced at {args.list_think:g} s), {args.records} jobs kept; "
             f"{args.seconds:g} s windows, median of {args.runs} runs; one worker busy with retargets throughout; "
             f"client: {args.client} (one process on the same machine); load average at the end "
             f"{os.getloadavg()[0]:.1f} (other work on the machine counts)",
             "", "| code | request | p50 ms | p99 ms | req/s | errors | job running |", "|---|---|---:|---:|---:|---:|---|"]
    for code, windows in results.items():
        for name, runs in windows.items():
            p50 = statistics.median(r[0] for r in runs)
            p99 = statistics.median(r[1] for r in runs)
            rate = statistics.median(r[2] for r in runs)
            lines.append(f"| {code} | {name} | {p50:.1f} | {p99:.1f} | {rate:.0f} | {sum(r[3] for r in runs)} | "
                         f"{'yes' if all(r[4] for r in runs) else 'not always'} |")
    lines += ["", f"memory: {MEMORY_UPLOADS} uploads of a 5 MB hair file ({SMALL_UPLOAD_STRANDS:,} strands) at once, "
                  f"resident memory sampled every {SAMPLE_SECONDS * 1000:g} ms (median of {args.runs} runs; the API "
                  "and its children: the processes it started, the validation pool's)", "",
              "| code | API before MB | API peak MB | API + children peak MB | 5 MB uploads answered | "
              f"{LARGE_UPLOADS} x 28 MB uploads answered (s) |", "|---|---:|---:|---:|---|---|"]
    for code, runs in memory.items():
        before, api, tree = (statistics.median(r[index] for r in runs) / 2**20 for index in range(3))
        small = ", ".join(f"{count} x {status}" for status, count in sorted(collections.Counter(
            status for r in runs for status in r[3]).items()))
        large = ", ".join(f"{count} x {status}" for status, count in sorted(collections.Counter(
            status for r in runs for status in r[4]).items()))
        lines.append(f"| {code} | {before:.0f} | {api:.0f} | {tree:.0f} | {small} | {large} "
                     f"({statistics.median(r[5] for r in runs):.1f}) |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["populate"]:
        populate(argv[1], int(argv[2]), argv[3])
        return 0
    if argv[:1] == ["upload"]:
        return upload_main(argv[1], argv[2], argv[3:])
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--records", type=int, default=10_000, help="job records kept")
    parser.add_argument("--pollers", type=int, default=100, help="concurrent pollers of GET /v1/jobs/{id}")
    parser.add_argument("--think", type=float, default=0.5, help="seconds a paced poller waits between polls")
    parser.add_argument("--list-think", type=float, default=1.0,
                        help="seconds a paced listing client (a dashboard refreshing) waits between listings")
    parser.add_argument("--list-clients", type=int, default=10, help="concurrent clients of the listings")
    parser.add_argument("--seconds", type=float, default=8.0, help="length of one measurement window")
    parser.add_argument("--runs", type=int, default=3, help="runs of every window (the median is reported)")
    parser.add_argument("--client", choices=("raw", "httpx"), default="raw",
                        help="the measuring client: a minimal asyncio HTTP/1.1 one, or httpx (see RawConnection)")
    parser.add_argument("--baseline-ref", help="also measure the code of this git revision, first")
    parser.add_argument("--serve-args", default="", help="extra arguments of `hairport serve` (this tree only)")
    args = parser.parse_args(argv)
    args.serve_args = args.serve_args.split()
    results, memory = {}, {}
    with tempfile.TemporaryDirectory(prefix="hairport-bench-grooms-") as folder:
        grooms = upload_grooms(Path(folder))
    for ref in ([args.baseline_ref] if args.baseline_ref else []) + [None]:
        code = ref or f"this tree {' '.join(args.serve_args)}".strip()
        print(f"measuring {code} ...", flush=True)
        results[code], memory[code] = run(ref, args, grooms)
    print(table(results, memory, args))
    return 0


if __name__ == "__main__":
    sys.exit(main())
