"""One job over several workers, and batches: wall time with 1, 2 and 4 worker processes, the per-chunk
overhead, and the throughput of a 4 x 4 batch with and without the per-target cache.

Starts its own ``redis-server`` (a free port, nothing on disk) and ``hairport worker`` processes (one
child each, kernels loaded from numba's cache) on a temporary storage folder per configuration; the API
runs in this process (FastAPI's test client). Inputs are the MakeHuman characters and "long" grooms of
``bench/table4.py``.

* **One job**: for each ``--sizes`` groom (average female -> heavy male, 300 guides), the wall time from
  submit to success of one multi-scale retarget with ``--workers`` worker processes (median of
  ``--runs``), chunks of ``HAIRPORT_FINE_CHUNK_PARTICLES`` (the default unless ``--chunk``); and, as the
  reference in the same run, the same job with one worker and no chunks (the fine level in the job's own
  run). From the job's record: chunks, workers that solved them, the fine level's seconds, and the
  per-chunk overhead (a chunk task's seconds beyond its solve: loading the artifact and the target,
  building the distance grid and the chunk's problem, writing its points).
* **Batch**: ``--grid`` grooms of ``--batch-particles`` particles x the four other MakeHuman bodies as
  targets, one batch request, with ``--batch-workers`` worker processes; pairs per minute, with the
  per-target cache (``HAIRPORT_TARGET_CACHE=true``, the default) and without (false). Each configuration
  starts fresh workers (empty in-process caches).

    python bench/distributed.py [--sizes 1e6 3e6] [--workers 1 2 4] [--runs 3] [--grid 4]

Prints tables; not a test.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))
from service_load import free_port  # noqa: E402 - bench/service_load.py, beside this script
from table4 import SOURCE, STYLE, TARGET, _machine, groom_shape  # noqa: E402

KEY = "bench-key"
AUTH = {"Authorization": f"Bearer {KEY}"}
START_SECONDS = 120.0
JOB_SECONDS = 3600.0
GUIDES = 300


def wait_until(check, what: str, seconds: float = START_SECONDS, pause: float = 0.2):
    deadline = time.monotonic() + seconds
    while True:
        with contextlib.suppress(Exception):
            value = check()
            if value:
                return value
        if time.monotonic() > deadline:
            raise SystemExit(f"bench: {what} timed out")
        time.sleep(pause)


class Deployment:
    """Redis, a storage folder, the API in-process and ``workers`` worker processes."""

    def __init__(self, workers: int, env: dict[str, str]):
        self.folder = Path(tempfile.mkdtemp(prefix="hairport-bench-dist-"))
        port = free_port()
        self.redis = subprocess.Popen([shutil.which("redis-server"), "--port", str(port), "--bind", "127.0.0.1",
                                       "--save", "", "--appendonly", "no", "--dir", str(self.folder)],
                                      stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        self.env = {**os.environ, **env, "HAIRPORT_REDIS_URL": f"redis://127.0.0.1:{port}/0",
                    "HAIRPORT_STORAGE_DIR": str(self.folder / "storage"), "HAIRPORT_API_KEYS": KEY,
                    "HAIRPORT_MAX_UPLOAD_BYTES": str(4 * 1024**3)}
        (self.folder / "storage").mkdir()
        self.saved = {name: os.environ.get(name) for name in self.env if name.startswith("HAIRPORT_")}
        for name in self.saved:  # the API in this process reads its settings from the environment
            os.environ[name] = self.env[name]
        from fastapi.testclient import TestClient

        from hairport.service.app import create_app
        from hairport.settings import Settings, get_settings

        get_settings.cache_clear()
        self.client = TestClient(create_app(Settings()))
        self.workers = [subprocess.Popen(
            [sys.executable, "-m", "hairport.cli", "worker", "--concurrency", "1", "--no-warmup",
             "--hostname", f"b{index}@%h", "--loglevel", "WARNING"], env=self.env, stdout=subprocess.DEVNULL,
            stderr=open(self.folder / f"worker{index}.log", "wb"), start_new_session=True)
            for index in range(workers)]
        wait_until(lambda: self.client.get("/readyz").status_code == 200, "workers")

    def close(self) -> None:
        for process in self.workers:
            with contextlib.suppress(ProcessLookupError):
                os.killpg(process.pid, 9)
            process.wait()
        self.redis.kill()
        self.redis.wait()
        shutil.rmtree(self.folder, ignore_errors=True)
        for name, value in self.saved.items():  # the next configuration starts from the caller's environment
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value

    def upload_character(self, path: Path) -> str:
        response = self.client.post("/v1/characters", headers=AUTH, files={
            "mesh": (path.name, path.read_bytes()),
            "skeleton": (f"{path.stem}.skeleton.json", path.with_suffix(".skeleton.json").read_bytes())})
        assert response.status_code == 201, response.text
        return response.json()["id"]

    def upload_hairstyle(self, source_id: str, hair: Path) -> str:
        response = self.client.post("/v1/hairstyles", headers=AUTH, files={"hair": (hair.name, hair.read_bytes())},
                                    data={"source_character_id": source_id, "guides": str(GUIDES)})
        assert response.status_code == 201, response.text
        hairstyle = response.json()["id"]
        wait_until(lambda: self.client.get(f"/v1/hairstyles/{hairstyle}", headers=AUTH).json()["preprocessing"][
            "state"] == "ready", "preprocessing", JOB_SECONDS, 0.5)
        return hairstyle

    def job(self, hairstyle: str, target: str) -> dict:
        """One retarget from submit to success: its record and wall seconds."""
        began = time.perf_counter()
        job = self.client.post("/v1/retargets", headers=AUTH, json={
            "hairstyle_id": hairstyle, "target_character_ids": [target], "output_format": "npz"}).json()["jobs"][0]
        done = wait_until(lambda: (body := self.client.get(f"/v1/jobs/{job['id']}", headers=AUTH).json())["state"]
                          in ("succeeded", "failed", "cancelled") and body, "job", JOB_SECONDS, 0.05)
        assert done["state"] == "succeeded", done
        return {"wall": time.perf_counter() - began, "job": done}


def write_inputs(folder: Path, sizes: list[int], grid: int, batch_particles: int) -> dict:
    from hairport.solver.io.hair import write_hair
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import PRESETS, build_character, write_character

    characters = {}
    for name in PRESETS:
        write_character(build_character(PRESETS[name]), folder / f"{name}.obj", folder / f"{name}.skeleton.json")
        characters[name] = folder / f"{name}.obj"
    source = build_character(PRESETS[SOURCE])
    grooms = {}
    for size in sizes:
        strands, per_strand = groom_shape(size)
        write_hair(folder / f"long-{size}.npz", generate_groom(source, STYLE, strands, per_strand, seed=0))
        grooms[size] = folder / f"long-{size}.npz"
    strands, per_strand = groom_shape(batch_particles)
    batch = []
    for seed in range(grid):
        write_hair(folder / f"batch-{seed}.npz", generate_groom(source, STYLE, strands, per_strand, seed=seed))
        batch.append(folder / f"batch-{seed}.npz")
    return {"characters": characters, "grooms": grooms, "batch": batch}


def one_job(inputs: dict, size: int, workers: int, runs: int, env: dict[str, str]) -> dict:
    deployment = Deployment(workers, env)
    try:
        source = deployment.upload_character(inputs["characters"][SOURCE])
        target = deployment.upload_character(inputs["characters"][TARGET])
        hairstyle = deployment.upload_hairstyle(source, inputs["grooms"][size])
        deployment.job(hairstyle, target)  # every worker process loads the artifact and the target once
        measured = [deployment.job(hairstyle, target) for _ in range(runs)]
    finally:
        deployment.close()
    walls = [entry["wall"] for entry in measured]
    last = measured[int(min(range(len(walls)), key=lambda i: abs(walls[i] - statistics.median(walls))))]["job"]
    chunks = last.get("chunks") or []
    overheads = [chunk["seconds"] - chunk["solve_seconds"] for chunk in chunks
                 if chunk.get("solve_seconds") is not None and chunk["worker"] != last["worker"]]
    return {"wall": statistics.median(walls), "fine": last["timings"]["fine_solve"],
            "chunks": len(chunks), "workers": len({chunk["worker"] for chunk in chunks}) or 1,
            "overhead": statistics.median(overheads) if overheads else None}


def batch_throughput(inputs: dict, workers: int, cache: bool, runs: int) -> dict:
    from hairport.solver.synthetic.makehuman import PRESETS

    env = {"HAIRPORT_TARGET_CACHE": "true" if cache else "false"}
    rates, built = [], []
    for _ in range(runs):
        deployment = Deployment(workers, env)
        try:
            source = deployment.upload_character(inputs["characters"][SOURCE])
            targets = [deployment.upload_character(inputs["characters"][name]) for name in PRESETS if name != SOURCE]
            hairstyles = [deployment.upload_hairstyle(source, groom) for groom in inputs["batch"]]
            began = time.perf_counter()
            batch = deployment.client.post("/v1/batches", headers=AUTH, json={
                "hairstyle_ids": hairstyles, "target_character_ids": targets, "output_format": "npz"}).json()
            done = wait_until(lambda: (body := deployment.client.get(f"/v1/batches/{batch['id']}", headers=AUTH)
                                       .json())["state"] == "done" and body, "batch", JOB_SECONDS, 0.1)
            seconds = time.perf_counter() - began
            assert done["counts"]["succeeded"] == len(hairstyles) * len(targets), done["counts"]
            rates.append(60.0 * len(done["jobs"]) / seconds)
            timings = [deployment.client.get(job["links"]["self"], headers=AUTH).json()["timings"]
                       for job in done["jobs"]]
            built.append(sum(t.get("prepare", 0.0) + t.get("target_cache_build", 0.0) + t.get("target_cache_load", 0.0)
                             for t in timings))
        finally:
            deployment.close()
    return {"pairs_per_minute": statistics.median(rates), "built": statistics.median(built)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", nargs="+", default=["1e6", "3e6"], help="particles of the one-job grooms")
    parser.add_argument("--workers", nargs="+", type=int, default=[1, 2, 4], help="worker processes")
    parser.add_argument("--runs", type=int, default=3, help="jobs (or batches) per configuration (median)")
    parser.add_argument("--chunk", type=int, default=None, help="HAIRPORT_FINE_CHUNK_PARTICLES (default: the setting's)")
    parser.add_argument("--grid", type=int, default=4, help="grooms of the batch (x the 4 other bodies)")
    parser.add_argument("--batch-particles", type=float, default=2e4, help="particles of each batch groom")
    parser.add_argument("--batch-workers", type=int, default=2, help="worker processes for the batch")
    parser.add_argument("--skip-batch", action="store_true")
    args = parser.parse_args()
    sizes = [int(float(size)) for size in args.sizes]
    print(_machine())
    with tempfile.TemporaryDirectory(prefix="hairport-bench-inputs-") as folder:
        inputs = write_inputs(Path(folder), sizes, args.grid, int(args.batch_particles))
        chunk_env = {} if args.chunk is None else {"HAIRPORT_FINE_CHUNK_PARTICLES": str(args.chunk)}
        print("\none job (MakeHuman average female -> heavy male, 'long', 300 guides): wall seconds submit -> "
              "succeeded, median of", args.runs)
        print(f"{'particles':>10} {'workers':>8} {'chunks':>7} {'solved by':>10} {'wall s':>8} {'fine s':>8} "
              f"{'vs 1 task':>10} {'chunk overhead s':>17}")
        for size in sizes:
            reference = one_job(inputs, size, 1, args.runs, {"HAIRPORT_FINE_CHUNK_PARTICLES": str(10**9)})
            print(f"{size:>10,} {1:>8} {'1 task':>7} {1:>10} {reference['wall']:>8.2f} {reference['fine']:>8.2f} "
                  f"{1.0:>9.2f}x {'-':>17}", flush=True)
            for workers in args.workers:
                row = one_job(inputs, size, workers, args.runs, chunk_env)
                overhead = "-" if row["overhead"] is None else f"{row['overhead']:.2f}"
                print(f"{size:>10,} {workers:>8} {row['chunks']:>7} {row['workers']:>10} {row['wall']:>8.2f} "
                      f"{row['fine']:>8.2f} {row['wall'] / reference['wall']:>9.2f}x {overhead:>17}", flush=True)
        if not args.skip_batch:
            print(f"\nbatch: {args.grid} grooms of {int(args.batch_particles):,} particles x 4 MakeHuman bodies, "
                  f"{args.batch_workers} worker processes, median of {args.runs} batches")
            print(f"{'target cache':>13} {'pairs/min':>10} {'target setup s':>15}  (summed over the jobs: prepare + cache)")
            for cache in (True, False):
                row = batch_throughput(inputs, args.batch_workers, cache, args.runs)
                print(f"{'on' if cache else 'off':>13} {row['pairs_per_minute']:>10.1f} {row['built']:>15.2f}",
                      flush=True)


if __name__ == "__main__":
    main()
