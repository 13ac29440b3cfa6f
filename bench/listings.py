"""Listing cost: ``GET /v1/batches``, ``/v1/characters``, ``/v1/hairstyles`` and ``/v1/jobs`` against the jobs
per batch and the records of other owners kept.

Each scenario is a fresh storage with one owner's ``--batches`` batches of ``jobs/batch`` jobs (10
hairstyles x the targets that make them, the jobs in a mix of states, running ones part-way), ``--own``
characters and hairstyles of that owner, and ``others`` records of every kind (characters, hairstyles,
batches of one job, jobs) of other owners, all written through the Repository as the API and the workers
write them (so that 10^4 records take seconds, not hours of solving). The app runs in this process
(FastAPI's TestClient, Celery's in-memory broker: a listing sends no task); each figure is the median of
``--runs`` requests after a few warm-up ones, in milliseconds, with the response's size in kB; the
scenarios' requests alternate, so that other load on the machine weighs on each alike. The last columns
are the ratios of the scenarios to the first one.

    python bench/listings.py
    python bench/listings.py --runs 31 --big-batch 1000 --others 10000
"""

from __future__ import annotations

import argparse
import contextlib
import random
import statistics
import tempfile
import time
from pathlib import Path

from hairport.records import (
    JOB_STATES,
    RUNNING,
    TERMINAL_STATES,
    BatchRecord,
    BlobRef,
    CharacterRecord,
    HairstyleRecord,
    JobRecord,
    PreprocessSettings,
)
from hairport.repository import Repository
from hairport.storage import LocalStorage

KEY = "bench-key"
AUTH = {"Authorization": f"Bearer {KEY}"}
PAGE = 100
#: hairstyles of a batch (its other side is its targets): 10 jobs are 10 x 1, 1,000 are 10 x 100
HAIRSTYLES_PER_BATCH = 10
#: requests of each listing before the timed ones (the app's first requests build what it caches)
WARMUP = 5
LISTINGS = ("/v1/batches", "/v1/characters", "/v1/hairstyles", "/v1/jobs")


def character(number: int, owner: str) -> CharacterRecord:
    return CharacterRecord(id=f"c{number:031x}", owner=owner, created_at=1000.0 + number,
                           mesh=BlobRef(sha256=f"{number:064x}", suffix=".obj", size=1000), vertices=3, faces=1,
                           bones=["head"])


def hairstyle(number: int, owner: str) -> HairstyleRecord:
    return HairstyleRecord(id=f"h{number:031x}", owner=owner, created_at=1000.0 + number,
                           source_character_id=f"c{number:031x}", hair=BlobRef(sha256=f"{number:064x}", suffix=".data"),
                           format="data", units="m", options=PreprocessSettings(k=5, guides=20),
                           artifact_key=f"{number:064x}", strands=2, particles=4)


def job(number: int, owner: str, batch_id: str | None, rng: random.Random) -> JobRecord:
    state = rng.choice(JOB_STATES)
    return JobRecord(id=f"{number:032x}", owner=owner, state=state, hairstyle_id="h" * 32,
                     target_character_id="c" * 32, options={"max_iterations": 50},
                     preprocess_options=PreprocessSettings(k=5, guides=20), artifact_key="a" * 64,
                     output_format="data", created_at=1000.0 + number, updated_at=1000.0 + number,
                     progress=1.0 if state in TERMINAL_STATES else rng.random() if state == RUNNING else 0.0,
                     finished_at=2000.0 + number if state in TERMINAL_STATES else None, batch_id=batch_id)


def populate(repository: Repository, owner: str, batches: int, per_batch: int, own: int, others: int) -> None:
    rng = random.Random(0)
    numbers = iter(range(10**9))
    # a batch's shape: up to HAIRSTYLES_PER_BATCH hairstyles x the targets that make its jobs
    hairstyles = next(count for count in range(min(HAIRSTYLES_PER_BATCH, per_batch), 0, -1) if per_batch % count == 0)
    for index in range(batches):
        batch_id = f"b{index:031x}"
        ids = []
        for _ in range(per_batch):
            record = job(next(numbers), owner, batch_id, rng)
            repository.create_job(record)
            ids.append(record.id)
        repository.put(BatchRecord(id=batch_id, owner=owner, created_at=1000.0 + index,
                                   hairstyle_ids=[f"h{n:031x}" for n in range(hairstyles)],
                                   target_character_ids=[f"c{n:031x}" for n in range(per_batch // hairstyles)],
                                   output_format="data", job_ids=ids), batch_id)
    for number in range(own):
        repository.put(character(number, owner), f"c{number:031x}")
        repository.put(hairstyle(number, owner), f"h{number:031x}")
    for number in range(own, own + others):
        stranger = f"other{number % 7}"
        repository.put(character(number, stranger), f"c{number:031x}")
        repository.put(hairstyle(number, stranger), f"h{number:031x}")
        record = job(next(numbers), stranger, f"b{number:031x}", rng)
        repository.create_job(record)
        repository.put(BatchRecord(id=f"b{number:031x}", owner=stranger, created_at=1000.0 + number,
                                   hairstyle_ids=["h" * 32], target_character_ids=["c" * 32], output_format="data",
                                   job_ids=[record.id]), f"b{number:031x}")


def client_of(storage: Path):
    """A TestClient of the app over ``storage`` (Celery's in-memory broker: a listing sends no task)."""
    from fastapi.testclient import TestClient

    from hairport.service.app import create_app
    from hairport.settings import Settings
    from hairport.worker.app import MEMORY_BROKER, make_celery
    from hairport.worker.queue import TaskQueue

    settings = Settings(storage_dir=storage, api_keys=KEY)
    return TestClient(create_app(settings, readiness=lambda: {}, queue_depths=lambda: {},
                                 queue=TaskQueue(make_celery(settings, MEMORY_BROKER))))


def measure(storages: dict[str, Path], runs: int) -> dict[str, dict[str, tuple[float, float]]]:
    """``{scenario: {listing: (median ms, kB)}}``. The scenarios' requests alternate (run by run), so that
    a load that comes and goes on the machine weighs on each scenario alike."""
    clients = {name: client_of(folder) for name, folder in storages.items()}
    sizes, samples = {}, {(name, path): [] for name in storages for path in LISTINGS}
    for name, client in clients.items():
        for path in LISTINGS:
            for _ in range(WARMUP):
                response = client.get(f"{path}?limit={PAGE}", headers=AUTH)
                assert response.status_code == 200, response.text
            sizes[name, path] = len(response.content) / 1e3
    for _ in range(runs):
        for name, client in clients.items():
            for path in LISTINGS:
                began = time.perf_counter()
                client.get(f"{path}?limit={PAGE}", headers=AUTH)
                samples[name, path].append((time.perf_counter() - began) * 1e3)
    return {name: {path: (statistics.median(samples[name, path]), sizes[name, path]) for path in LISTINGS}
            for name in storages}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=21, help="requests per listing and scenario (median)")
    parser.add_argument("--batches", type=int, default=10, help="the owner's batches")
    parser.add_argument("--small-batch", type=int, default=10, help="jobs per batch of the first scenario")
    parser.add_argument("--big-batch", type=int, default=1000, help="jobs per batch of the second scenario")
    parser.add_argument("--own", type=int, default=20, help="the owner's characters and hairstyles")
    parser.add_argument("--few-others", type=int, default=10, help="other owners' records of each kind (first two)")
    parser.add_argument("--others", type=int, default=10_000, help="other owners' records of each kind (third)")
    args = parser.parse_args()
    from hairport.service.auth import owner_of

    owner = owner_of(KEY)
    scenarios = {
        f"{args.small_batch} jobs/batch, {args.few_others} others": (args.small_batch, args.few_others),
        f"{args.big_batch} jobs/batch, {args.few_others} others": (args.big_batch, args.few_others),
        f"{args.small_batch} jobs/batch, {args.others} others": (args.small_batch, args.others),
    }
    with contextlib.ExitStack() as stack:
        storages = {}
        for name, (per_batch, others) in scenarios.items():
            folder = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="hairport-bench-")))
            began = time.perf_counter()
            populate(Repository(LocalStorage(folder, durable=False)), owner, args.batches, per_batch, args.own, others)
            print(f"{name}: stored in {time.perf_counter() - began:.0f} s", flush=True)
            storages[name] = folder
        table = measure(storages, args.runs)
    names = list(table)
    print(f"\nmedian of {args.runs} requests (ms) and response size (kB); page of {PAGE}; "
          f"{args.batches} batches and {args.own} characters and hairstyles of the caller")
    print("| listing | " + " | ".join(names) + " | " + " | ".join(f"x ({n})" for n in names[1:]) + " |")
    print("|---" * (1 + 2 * len(names) - 1) + "|")
    for path in LISTINGS:
        base = table[names[0]][path][0]
        cells = [f"{table[n][path][0]:.1f} ms, {table[n][path][1]:.0f} kB" for n in names]
        ratios = [f"{table[n][path][0] / base:.2f}" for n in names[1:]]
        print(f"| GET {path}?limit={PAGE} | " + " | ".join(cells) + " | " + " | ".join(ratios) + " |")


if __name__ == "__main__":
    main()
