"""The job index's reads, SQLite (what hairport uses) against Redis sorted sets (the alternative).

Both hold ``--jobs`` jobs of one owner in random states; each answers a page of 50 newest first
(all states, and one state) with its total, and the counts by state. Redis: one sorted set per
owner and one per (owner, state), scored by creation time, and a hash of counts; a page is
``ZREVRANGE`` + ``ZCARD`` in one pipeline. It starts its own redis-server (free port, nothing on
disk). Times are the median over ``--repeat`` calls, in microseconds, client included.

    python bench/job_index.py --jobs 10000
"""

from __future__ import annotations

import argparse
import random
import shutil
import socket
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

from hairport.records import JOB_STATES
from hairport.storage.index import JobRow, SqliteIndex

OWNER = "kowner"
PAGE = 50


def timed(call, repeat: int) -> float:
    samples = []
    for _ in range(repeat):
        began = time.perf_counter()
        call()
        samples.append((time.perf_counter() - began) * 1e6)
    return statistics.median(samples)


def main() -> None:
    import redis

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--jobs", type=int, default=10_000)
    parser.add_argument("--repeat", type=int, default=2000)
    args = parser.parse_args()
    rng = random.Random(0)
    rows = [JobRow(f"{n:032x}", OWNER, rng.choice(JOB_STATES), 1000.0 + n, 1000.0 + n) for n in range(args.jobs)]
    with tempfile.TemporaryDirectory() as folder:
        index = SqliteIndex(Path(folder), lambda: rows, durable=False)
        index.job_counts()  # created and filled from the rows
        with socket.socket() as probe:
            probe.bind(("127.0.0.1", 0))
            port = probe.getsockname()[1]
        server = subprocess.Popen([shutil.which("redis-server"), "--port", str(port), "--save", "", "--appendonly",
                                   "no", "--dir", folder], stdout=subprocess.DEVNULL)
        try:
            client = redis.Redis(port=port)
            while True:
                try:
                    client.ping()
                    break
                except redis.ConnectionError:
                    time.sleep(0.05)
            pipe = client.pipeline()
            for row in rows:
                pipe.zadd(f"jobs:{OWNER}", {row.id: row.created_at})
                pipe.zadd(f"jobs:{OWNER}:{row.state}", {row.id: row.created_at})
                pipe.hincrby("counts", row.state, 1)
            pipe.execute()

            def redis_page(key: str):
                pipe = client.pipeline()
                pipe.zrevrange(key, 0, PAGE - 1)
                pipe.zcard(key)
                return pipe.execute()

            results = {
                "page of 50 + total": (timed(lambda: index.job_page(OWNER, None, PAGE, 0), args.repeat),
                                       timed(lambda: redis_page(f"jobs:{OWNER}"), args.repeat)),
                "page of 50 in a state + total": (timed(lambda: index.job_page(OWNER, "succeeded", PAGE, 0),
                                                        args.repeat),
                                                  timed(lambda: redis_page(f"jobs:{OWNER}:succeeded"), args.repeat)),
                "counts by state": (timed(index.job_counts, args.repeat), timed(lambda: client.hgetall("counts"),
                                                                            args.repeat)),
            }
        finally:
            server.terminate()
            server.wait()
    print(f"{args.jobs} jobs of one owner, median of {args.repeat} calls (µs)")
    print("| read | SQLite (WAL, file) | Redis sorted sets |\n|---|---:|---:|")
    for name, (sqlite_us, redis_us) in results.items():
        print(f"| {name} | {sqlite_us:.0f} | {redis_us:.0f} |")


if __name__ == "__main__":
    main()
