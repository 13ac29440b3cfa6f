"""End-to-end latency of one retarget as an avatar backend sees it: a 10^5-particle groom, already
preprocessed (its artifact cached), retargeted onto a new body by a warm worker.

Starts its own services on free ports as ``bench/multihost.py`` does (its :class:`Deployment`, with one
worker): a ``redis-server`` (nothing on disk), a real ``hairport serve`` and one real ``hairport worker
--concurrency 1 --no-warmup`` (kernels from numba's cache), on a temporary storage folder (the default
deployment: one folder, records and their SQLite index in it). With ``--deployment s3`` the blobs are in a
SeaweedFS server and the records in a PostgreSQL database instead, each process with a cache folder of
its own (multihost.py's deployment B, its servers started by the tests' harness).

Inputs, as ``bench/table4.py``'s 10^5 row: the MakeHuman average female as the source, a "long" groom of
2,000 strands x 50 particles on her (300 guides), and heavy males as targets. All are uploaded through the
API and the groom is preprocessed before anything is timed. Then 2 warm-up jobs, then ``--jobs`` retargets
one at a time, each measured from just before ``POST /v1/retargets`` (npz output) to:

* *succeeded*: the first ``GET /v1/jobs/{id}`` that answers ``succeeded``. The job is polled every
  :data:`POLL_SECONDS`, so this figure is late by up to that (plus one poll's round trip); the job
  record's ``finished_at`` (the worker's clock, this machine's) gives the same end without that error;
* *downloaded*: ``GET /v1/jobs/{id}/result?format=npz`` read to its last byte, after *succeeded*.

Also per job: the queue wait (the record's ``started_at`` minus the submit), and the job's own ``timings``
(worker/runner.py: the solver's stages, the per-target cache, and ``job``, the whole run in the worker
from its start to its outputs stored); the table prints the median of every entry, ``job`` minus
``solve`` (the time beyond the solve) and the part of ``job`` no entry times (loading the inputs,
writing and storing the outputs).

The service keeps no result cache: every ``POST /v1/retargets`` makes a new job that solves (an
``Idempotency-Key``, not sent here, would replay a request's jobs). What a worker does keep is the
target's: its collision surface (in the storage, by the body's content: ``worker/bodies.py``) and its
collision query (in the process, the last 4 bodies). So that every job meets a body the worker has not
seen, as a new avatar is, each job (the warm-ups too) has a target of its own: the heavy male with
``weight`` lowered by :data:`BODY_WEIGHT_STEP` per job (each step moves vertices by at most 0.13 mm,
21 steps by 2.7 mm; the head not at all): a new body by its content, with about the same solve.
``--bodies repeat`` alternates two bodies instead (the target's caches warm: what a retarget of a known
body costs). The artifact is the same for every job: a warm worker keeps the last 2 loaded
(``worker/loading.adaptable_at``), as it does for a groom retargeted onto many bodies.

Each figure is over the ``--jobs`` jobs (p50, p95, max; the timings' medians). The worker runs at the
deployment's niceness (``HAIRPORT_WORKER_NICENESS``, 10 unless ``--niceness``): on a machine shared
with other work it yields to it. The services run the installed tree (the header says its commit and
whether it has uncommitted changes), or with ``--ref REV`` the code of that revision
(``service_load.source_tree``).

    python bench/latency.py                          # 20 jobs, a new body each, one folder
    python bench/latency.py --jobs 5 --bodies repeat  # a quick check, bodies the worker knows
    python bench/latency.py --deployment s3          # S3 (SeaweedFS) + PostgreSQL
    python bench/latency.py --ref HEAD               # the last commit, not the working tree

Prints a table; not a test. Times are wall-clock seconds on this machine.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "bench")]  # the other benches beside this script, tests.servers
from multihost import DONE, JOB_SECONDS, SETTLE_SECONDS, Deployment, fresh_database, preprocessed, s3_settings  # noqa: E402
from service_load import AUTH, percentile, source_tree, wait_until  # noqa: E402
from table4 import SOURCE, STYLE, TARGET, _machine, groom_shape  # noqa: E402

#: particles of the groom (table4's 10^5 row: 2,000 strands x 50)
PARTICLES = 100_000
#: guides of the hairstyle's preprocessing (table4's)
GUIDES = 300
#: seconds between two polls of a job being timed: the resolution of "succeeded"
POLL_SECONDS = 0.02
#: jobs run (and not timed) before the timed ones: the artifact loaded, the kernels loaded, the first
#: connections made
WARMUP_JOBS = 2
#: how much lighter each job's target is than the one before (MakeHuman's weight macro, 0-1): a body the worker
#: has not seen, of about the same solve
BODY_WEIGHT_STEP = 0.002
#: bodies alternated with ``--bodies repeat``
REPEATED_BODIES = 2
#: the result's format (read to the end by the client)
OUTPUT_FORMAT = "npz"
#: the timings entries within ``solve`` (the multi-scale solve's parts), not beside it
WITHIN_SOLVE = ("distance_grid", "coarse_solve", "fine_solve")


# ---------------------------------------------------------------------- the service


class OneWorker(Deployment):
    """multihost.py's deployment with one worker process (concurrency 1), ``w1``."""

    workers = 1


# ---------------------------------------------------------------------- inputs


def body_count(args) -> int:
    """Target bodies uploaded: one per job (the warm-ups' too), or :data:`REPEATED_BODIES`."""
    return WARMUP_JOBS + args.jobs if args.bodies == "new" else REPEATED_BODIES


def body_number(job: int, bodies: str) -> int:
    """The target body of job ``job`` (0-based, warm-ups first): its own, or one of :data:`REPEATED_BODIES`."""
    return job if bodies == "new" else job % REPEATED_BODIES


def write_inputs(folder: Path, bodies: int) -> None:
    """The source (``source.obj`` + skeleton), ``bodies`` targets (``target-<n>.obj`` + skeleton: the heavy
    male ever lighter) and the groom (``groom.data``)."""
    from hairport.solver.io.hair import write_hair
    from hairport.solver.synthetic.groom import generate_groom
    from hairport.solver.synthetic.makehuman import PRESETS, build_character, write_character

    source = build_character(PRESETS[SOURCE], name=SOURCE)
    write_character(source, folder / "source.obj", folder / "source.skeleton.json")
    heavy = PRESETS[TARGET]
    for number in range(bodies):
        body = build_character(dataclasses.replace(heavy, weight=heavy.weight - BODY_WEIGHT_STEP * number),
                               name=f"{TARGET}-{number}")
        write_character(body, folder / f"target-{number}.obj", folder / f"target-{number}.skeleton.json")
    write_hair(folder / "groom.data", generate_groom(source, STYLE, *groom_shape(PARTICLES), seed=0))


def upload_character(client, folder: Path, name: str) -> str:
    response = client.post("/v1/characters", files={
        "mesh": (f"{name}.obj", (folder / f"{name}.obj").read_bytes()),
        "skeleton": (f"{name}.skeleton.json", (folder / f"{name}.skeleton.json").read_bytes())})
    response.raise_for_status()
    return response.json()["id"]


def upload_inputs(client, deployment: Deployment, folder: Path, bodies: int) -> dict:
    """Every input uploaded, the groom preprocessed: ``{"source": id, "targets": [ids], "hairstyle": id}``."""
    ids = {"source": upload_character(client, folder, "source")}
    ids["targets"] = [upload_character(client, folder, f"target-{number}") for number in range(bodies)]
    response = client.post("/v1/hairstyles", data={"source_character_id": ids["source"], "guides": str(GUIDES)},
                           files={"hair": ("groom.data", (folder / "groom.data").read_bytes())})
    response.raise_for_status()
    ids["hairstyle"] = response.json()["id"]
    wait_until(lambda: preprocessed(client, deployment, ids["hairstyle"]), "the preprocessing", JOB_SECONDS)
    return ids


# ---------------------------------------------------------------------- one job


def one_job(client, deployment: Deployment, hairstyle: str, target: str) -> dict:
    """One retarget from submit to succeeded (seen by a poll) and to its result read: seconds after the submit,
    the record's times (``queued``: to ``started_at``; ``finished``: to ``finished_at``), its timings."""
    submitted, began = time.time(), time.perf_counter()
    response = client.post("/v1/retargets", json={"hairstyle_id": hairstyle, "target_character_ids": [target],
                                                   "output_format": OUTPUT_FORMAT})
    response.raise_for_status()
    job_id = response.json()["jobs"][0]["id"]
    deadline = began + JOB_SECONDS
    while (job := client.get(f"/v1/jobs/{job_id}").json())["state"] not in DONE:
        if time.perf_counter() > deadline:
            raise deployment.failure(f"job {job_id} did not end within {JOB_SECONDS:g} s: {job}")
        time.sleep(POLL_SECONDS)
    succeeded = time.perf_counter() - began
    if job["state"] != "succeeded":
        raise deployment.failure(f"job {job_id} {job['state']}: {job.get('error')}")
    size = 0
    with client.stream("GET", f"/v1/jobs/{job_id}/result", params={"format": OUTPUT_FORMAT}) as result:
        result.raise_for_status()
        for chunk in result.iter_bytes():
            size += len(chunk)
    return {"succeeded": succeeded, "downloaded": time.perf_counter() - began,
            "queued": job["started_at"] - submitted, "finished": job["finished_at"] - submitted,
            "running": job["finished_at"] - job["started_at"], "bytes": size, "timings": job["timings"] or {},
            "penetrating": (job["metrics"] or {}).get("penetrating_particles")}


def run_jobs(deployment: Deployment, folder: Path, args) -> list[dict]:
    """Upload, warm up, then ``args.jobs`` timed jobs one at a time."""
    import httpx

    bodies = body_count(args)
    with httpx.Client(base_url=deployment.url, headers=AUTH, timeout=600) as client:
        began = time.perf_counter()
        ids = upload_inputs(client, deployment, folder, bodies)
        print(f"  {bodies + 1} characters and the groom uploaded, the groom preprocessed, in "
              f"{time.perf_counter() - began:.1f} s", flush=True)
        time.sleep(args.settle)
        jobs = []
        for number in range(WARMUP_JOBS + args.jobs):
            job = one_job(client, deployment, ids["hairstyle"], ids["targets"][body_number(number, args.bodies)])
            timed = number >= WARMUP_JOBS
            if timed:
                jobs.append(job)
            print(f"  {'job' if timed else 'warm-up'} {number + 1 - WARMUP_JOBS * timed}: {describe(job)}",
                  flush=True)
    return jobs


def describe(job: dict) -> str:
    stages = ", ".join(f"{name} {seconds:.2f}" for name, seconds in job["timings"].items())
    return (f"succeeded {job['succeeded']:.2f} s, downloaded {job['downloaded']:.2f} s (queued {job['queued']:.3f}, "
            f"running {job['running']:.2f}, {job['bytes'] / 1e6:.1f} MB); penetrating {job['penetrating']}; {stages}")


def run(inputs: Path, args) -> list[dict]:
    """The jobs, in a deployment started for them (and stopped)."""
    with tempfile.TemporaryDirectory(prefix="hairport-bench-latency-") as temp:
        # the code of --ref (exported, first on PYTHONPATH) or the installed tree, and the worker's niceness
        settings = {**source_tree(args.ref, Path(temp)),
                    **({} if args.niceness is None else {"HAIRPORT_WORKER_NICENESS": str(args.niceness)})}
        if args.deployment == "folder":
            return started(OneWorker(Path(temp), settings, shared_folder=True), inputs, args)
        from tests.servers.postgres import PostgresServer
        from tests.servers.seaweed import SeaweedServer

        with PostgresServer() as postgres, SeaweedServer() as seaweed:
            shared = s3_settings(seaweed, fresh_database(postgres.url), f"bench-{uuid.uuid4().hex[:8]}")
            return started(OneWorker(Path(temp), {**shared, **settings}, shared_folder=False), inputs, args)


def started(deployment: Deployment, inputs: Path, args) -> list[dict]:
    try:
        deployment.start()
        return run_jobs(deployment, inputs, args)
    finally:
        deployment.stop()


# ---------------------------------------------------------------------- the table


def untimed(timings: dict) -> float:
    """Seconds of ``job`` no other entry times: reading the inputs (the artifact, the target character and its
    frame) and writing and storing the outputs."""
    return timings["job"] - sum(seconds for name, seconds in timings.items()
                                if name != "job" and name not in WITHIN_SOLVE)


def git(*command: str) -> str:
    return subprocess.run(["git", "-C", str(ROOT), *command], capture_output=True, text=True, check=True).stdout.strip()


def code(ref: str | None) -> str:
    """The code measured, read before the services start (the tree may move on meanwhile): the commit ``ref``, or
    the installed tree's and whether it has uncommitted changes."""
    if ref is not None:
        return f"commit {ref}"
    changed = git("status", "--porcelain", "--untracked-files=no", "--", "hairport", "solver", "service", "worker")
    return f"the tree at {git('rev-parse', '--short', 'HEAD')}{' with uncommitted changes' if changed else ''}"


def table(jobs: list[dict], args, load: tuple[float, float]) -> str:
    def spread(values: list[float]) -> str:
        return f"{percentile(values, 50):.3f} | {percentile(values, 95):.3f} | {max(values):.3f}"

    niceness = args.niceness if args.niceness is not None else "10 (the default)"
    strands, per_strand = groom_shape(PARTICLES)
    bodies = "a new one each job" if args.bodies == "new" else f"{REPEATED_BODIES} alternated"
    lines = [f"hairport latency - {_machine()} - load average {load[0]:.1f} at the start, {load[1]:.1f} at the end "
             "(other work on the machine counts)",
             f"MakeHuman {SOURCE} -> {TARGET} ({args.bodies} bodies: {bodies}), '{STYLE}' groom {strands:,} strands x "
             f"{per_strand}, {GUIDES} guides, preprocessed before; code: {args.code}; deployment: {args.deployment}; "
             f"one worker (concurrency 1, niceness {niceness}); {OUTPUT_FORMAT} result; {WARMUP_JOBS} warm-up jobs, "
             f"then {len(jobs)} jobs one at a time; polled every {POLL_SECONDS * 1000:g} ms (\"succeeded\" is late by "
             "up to that)",
             "", "| submit -> | p50 s | p95 s | max s |", "|---|---:|---:|---:|"]
    for name, key in (("succeeded (seen by a poll)", "succeeded"), ("result downloaded", "downloaded"),
                      ("finished_at (the record)", "finished"), ("started_at (queue wait)", "queued")):
        lines.append(f"| {name} | {spread([job[key] for job in jobs])} |")
    lines.append(f"| (running: started_at -> finished_at) | {spread([job['running'] for job in jobs])} |")
    lines.append(f"| (download alone) | {spread([job['downloaded'] - job['succeeded'] for job in jobs])} |")
    names = list(dict.fromkeys(name for job in jobs for name in job["timings"]))
    lines += ["", f"the job's timings (worker/runner.py), median of {len(jobs)} (solve: the solve's parts)", "",
              "| entry | median s |", "|---|---:|"]
    for name in names:
        values = [job["timings"][name] for job in jobs if name in job["timings"]]
        count = "" if len(values) == len(jobs) else f" ({len(values)} jobs)"
        lines.append(f"| {'solve: ' if name in WITHIN_SOLVE else ''}{name}{count} | "
                     f"{statistics.median(values):.3f} |")
    lines.append(f"| job - solve (beyond the solve) | "
                 f"{statistics.median(job['timings']['job'] - job['timings']['solve'] for job in jobs):.3f} |")
    lines.append(f"| job - every other entry (untimed: loading, writing) | "
                 f"{statistics.median(untimed(job['timings']) for job in jobs):.3f} |")
    lines.append(f"| running - job (claiming the job: its record's write) | "
                 f"{statistics.median(job['running'] - job['timings']['job'] for job in jobs):.3f} |")
    penetrating = sorted({job["penetrating"] for job in jobs}, key=str)
    lines += ["", f"result {statistics.median(job['bytes'] for job in jobs) / 1e6:.1f} MB; penetrating particles: "
                  f"{', '.join(map(str, penetrating))}"]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--jobs", type=int, default=20, help="timed jobs (after the warm-up ones)")
    parser.add_argument("--bodies", choices=("new", "repeat"), default="new",
                        help=f"a new target body each job, or {REPEATED_BODIES} alternated")
    parser.add_argument("--deployment", choices=("folder", "s3"), default="folder",
                        help="one storage folder (SQLite), or SeaweedFS (S3) + PostgreSQL")
    parser.add_argument("--niceness", type=int, default=None,
                        help="the worker's HAIRPORT_WORKER_NICENESS (default: the deployment's, 10)")
    parser.add_argument("--ref", help="measure the code of this git revision (exported into a temporary folder, first "
                                      "on the services' PYTHONPATH; its kernels compiled by the warm-up jobs) instead "
                                      "of the installed tree")
    parser.add_argument("--settle", type=float, default=None,
                        help=f"seconds to wait after the uploads, before the first job (default 0; {SETTLE_SECONDS:g} "
                             "with --deployment s3: the servers' start-up work, see bench/multihost.py)")
    args = parser.parse_args(argv)
    if args.ref is not None:  # one commit for the export and the header, whatever the ref names later
        args.ref = git("rev-parse", "--short", args.ref)
    args.code = code(args.ref)
    if args.settle is None:
        args.settle = SETTLE_SECONDS if args.deployment == "s3" else 0.0
    # a SIGTERM ends the bench as Ctrl-C does: every server and process stopped, every folder removed
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(128 + signal.SIGTERM))
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="hairport-bench-latency-inputs-") as folder:
        began = time.perf_counter()
        write_inputs(Path(folder), body_count(args))
        print(f"inputs written in {time.perf_counter() - began:.1f} s; measuring ...", flush=True)
        jobs = run(Path(folder), args)
    print(table(jobs, args, (load, os.getloadavg()[0])))
    return 0


if __name__ == "__main__":
    sys.exit(main())
