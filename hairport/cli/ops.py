"""Operations commands: ``serve``, ``worker``, ``warmup``, ``purge``, ``reindex``, ``openapi`` and ``assets fetch``.

The web framework, Celery and the asset downloader are imported inside the commands that
use them, so that the other commands start without them.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from pathlib import Path

from hairport.outputs import OutputSet
from hairport.settings import Settings, get_settings

from .common import EXIT_BAD_INPUT

#: the API's application factory, as uvicorn imports it in each worker process
APP_FACTORY = "hairport.service.app:create_app"


def add_assets(sub) -> None:
    p = sub.add_parser("assets", help="manage the downloaded MakeHuman assets")
    asub = p.add_subparsers(dest="assets_command", required=True)
    f = asub.add_parser("fetch", help="download (once) and cache the CC0 MakeHuman assets")
    f.add_argument("--cache-dir", help="cache folder (default: $HAIRPORT_CACHE_DIR or ~/.cache/hairport)")
    f.set_defaults(run=cmd_assets_fetch)


def cmd_assets_fetch(args: argparse.Namespace) -> int:
    from hairport.solver.synthetic.assets import fetch_makehuman_assets

    path = fetch_makehuman_assets(Path(args.cache_dir) if args.cache_dir else None)
    print(path)
    return 0


def add_serve(sub) -> None:
    p = sub.add_parser("serve", help="run the HTTP API (uvicorn)")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--port", type=int, default=8000)
    p.add_argument("--embedded", action="store_true",
                   help="run a worker inside the server on an in-memory queue (no Redis; for a laptop)")
    p.add_argument("--workers", type=int, default=1,
                   help="API processes (uvicorn workers) sharing the port; each serves requests on its own event loop "
                        "and GIL (not with --embedded)")
    p.set_defaults(run=cmd_serve)


def cmd_serve(args: argparse.Namespace) -> int:
    import uvicorn

    from hairport.repository import Repository
    from hairport.service.app import create_app
    from hairport.service.auth import check_configuration
    from hairport.storage import open_storage
    from hairport.worker.queue import Sweeper, TaskQueue

    settings = get_settings()
    try:
        check_configuration(settings)
    except RuntimeError as error:
        print(f"hairport: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.workers < 1 or (args.embedded and args.workers != 1):
        print("hairport: error: --workers must be 1 or more, and 1 with --embedded (its queue is in memory)",
              file=sys.stderr)
        return EXIT_BAD_INPUT
    if args.workers > 1:  # each process builds its own app from the settings (uvicorn imports the factory)
        uvicorn.run(APP_FACTORY, factory=True, host=args.host, port=args.port, workers=args.workers)
        return 0
    if args.embedded:
        from hairport.worker.embedded import start_embedded_worker

        celery, thread = start_embedded_worker()
        app = create_app(readiness=lambda: {"worker": thread.is_alive()}, queue_depths=lambda: {},
                         queue=TaskQueue(celery))
    else:
        app = create_app()
    # the API sweeps too: stale jobs are found when every worker host is gone
    Sweeper(Repository(open_storage(settings)), app.state.queue, settings).start()
    print(f"hairport: deployment {app.state.deployment}, storage {settings.storage_dir}, broker "
          f"{app.state.queue.broker}", file=sys.stderr)
    uvicorn.run(app, host=args.host, port=args.port)
    return 0


def add_warmup(sub) -> None:
    p = sub.add_parser("warmup", help="compile the solver's kernels into numba's on-disk cache (or check they load)")
    p.set_defaults(run=cmd_warmup)


def cmd_warmup(args: argparse.Namespace) -> int:
    from hairport.solver import kernels

    done = kernels.warm_up()
    for name, seconds in sorted(done.seconds.items()):
        print(f"{name}: {seconds:.2f} s")
    print(f"{done.kernels} kernels: {done.compiled} signatures compiled, {done.loaded} loaded from the cache, "
          f"in {sum(done.seconds.values()):.1f} s")
    return 0


def start_warmup() -> subprocess.Popen:
    """``hairport warmup`` in a process of its own, not waited for: it fills the kernel cache
    while the caller starts up. Not in the caller's process: one that ran the parallel
    kernels must not fork (:mod:`hairport.solver.jit`), and a worker forks its pool."""
    return subprocess.Popen([sys.executable, "-m", "hairport.cli", "warmup"], stdout=subprocess.DEVNULL)


def add_worker(sub) -> None:
    p = sub.add_parser("worker", help="run a Celery worker against HAIRPORT_REDIS_URL")
    p.add_argument("--queues", default=None,
                   help="comma-separated queues to consume (default: every queue: preprocess, retarget, fine)")
    p.add_argument("--concurrency", type=int, default=1, help="jobs run at once (processes)")
    p.add_argument("--loglevel", default="INFO")
    p.add_argument("--hostname", default="hairport@%h", help="worker name (%%h: host name)")
    p.add_argument("--no-warmup", action="store_true",
                   help="do not compile the solver's kernels at start (the first job compiles what is not cached)")
    p.set_defaults(run=cmd_worker)


def cmd_worker(args: argparse.Namespace) -> int:
    from hairport.worker.app import QUEUES, configured_celery, queue_names

    settings = get_settings()
    if not settings.storage_dir.is_dir():
        # a worker on a folder that does not exist is on the wrong one (or the volume is not mounted):
        # it would make a new, empty deployment there and never see a job
        print(f"hairport: error: the storage folder {settings.storage_dir} does not exist (HAIRPORT_STORAGE_DIR): "
              "mount the deployment's storage, or start its API first", file=sys.stderr)
        return EXIT_BAD_INPUT
    wanted = list(QUEUES) if args.queues is None else [name.strip() for name in args.queues.split(",") if name.strip()]
    unknown = sorted(set(wanted) - set(QUEUES))
    if unknown or not wanted:
        print(f"hairport: error: unknown queues {', '.join(unknown) or '(none)'}: choose from {', '.join(QUEUES)}",
              file=sys.stderr)
        return EXIT_BAD_INPUT
    celery = configured_celery()
    if not args.no_warmup:
        start_warmup()
    names = queue_names(celery.hairport_deployment)
    celery.worker_main(["worker", "-Q", ",".join(names[name] for name in wanted), "-c", str(args.concurrency),
                        "--loglevel", args.loglevel, "-n", args.hostname])
    return 0


def add_purge(sub) -> None:
    p = sub.add_parser("purge", help="delete stored files and records older than HAIRPORT_RETENTION_DAYS, and stored "
                                     "files no record refers to older than HAIRPORT_ORPHAN_GRACE_SECONDS")
    p.set_defaults(run=cmd_purge)


def cmd_purge(args: argparse.Namespace) -> int:
    from hairport.repository import Repository
    from hairport.storage import open_storage, retention_seconds

    settings = get_settings()
    repository = Repository(open_storage(settings))
    removed = repository.purge(retention_seconds(settings.retention_days))
    orphans = repository.sweep_orphans(settings.orphan_grace_seconds)
    print(f"removed {removed} files older than {settings.retention_days:g} days and {orphans} stored files no record "
          f"refers to, older than {settings.orphan_grace_seconds:g} s, from {settings.storage_dir}")
    return 0


def add_reindex(sub) -> None:
    p = sub.add_parser("reindex", help="rebuild the record index (listings, batch and job counts, /metrics) from "
                                       "the records")
    p.set_defaults(run=cmd_reindex)


def cmd_reindex(args: argparse.Namespace) -> int:
    from hairport.repository import OWNED_KINDS, Repository
    from hairport.storage import open_storage
    from hairport.storage.index import JOBS

    settings = get_settings()
    rows = Repository(open_storage(settings)).rebuild_index()
    kinds = ", ".join(f"{rows.get(kind, 0)} {kind}" for kind in (JOBS, *OWNED_KINDS))
    print(f"indexed {kinds} of {settings.storage_dir}")
    return 0


def add_db(sub) -> None:
    p = sub.add_parser("db", help="the records' database (HAIRPORT_DATABASE_URL)")
    dsub = p.add_subparsers(dest="db_command", required=True)
    u = dsub.add_parser("upgrade", help="bring the database's schema to this hairport's version (records kept)")
    u.set_defaults(run=cmd_db_upgrade)


def cmd_db_upgrade(args: argparse.Namespace) -> int:
    from hairport.storage import Database, SchemaMismatch, StorageUnavailable, upgrade

    settings = get_settings()
    if not settings.database_url or not settings.database_url.startswith(("postgresql://", "postgres://")):
        print("hairport: error: HAIRPORT_DATABASE_URL names no PostgreSQL database (the records are in the storage "
              "folder, which needs no upgrade)", file=sys.stderr)
        return EXIT_BAD_INPUT
    database = Database(settings.database_url)
    try:
        before, after = upgrade(database)
    except (SchemaMismatch, StorageUnavailable) as error:
        print(f"hairport: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    state = "already at" if before == after else f"upgraded from schema version {before} to"
    print(f"{database.describe()}: {state} schema version {after}")
    return 0


def add_migrate(sub) -> None:
    p = sub.add_parser("migrate", help="copy a one-host deployment (HAIRPORT_STORAGE_DIR's records and blobs) into "
                                       "a database and an object store that several hosts share")
    p.add_argument("--to-database", required=True, metavar="URL", help="postgresql://user@host:port/name")
    p.add_argument("--to-storage", required=True, metavar="URL",
                   help="s3://bucket/prefix (credentials, region, endpoint: AWS_* or HAIRPORT_S3_*)")
    p.set_defaults(run=cmd_migrate)


def cmd_migrate(args: argparse.Namespace) -> int:
    from hairport.repository import Repository
    from hairport.storage import LocalStorage, SchemaMismatch, StorageUnavailable, object_store_for_url, open_records
    from hairport.storage.migrate import migrate

    settings = get_settings()
    if settings.database_url or settings.storage_url:
        print("hairport: error: migrate copies a deployment whose records and blobs are in its storage folder; "
              "unset HAIRPORT_DATABASE_URL and HAIRPORT_STORAGE_URL for it", file=sys.stderr)
        return EXIT_BAD_INPUT
    source = LocalStorage(settings.storage_dir)
    try:
        with tempfile.TemporaryDirectory(prefix="hairport-migrate-") as cache:
            target = LocalStorage(Path(cache), remote=object_store_for_url(args.to_storage, **settings.s3_overrides()),
                                  records=open_records(args.to_database))
            report = migrate(source, target, progress=lambda message: print(f"hairport: {message}", file=sys.stderr))
            indexed = Repository(target).rebuild_index()
    except (ValueError, SchemaMismatch, StorageUnavailable) as error:
        print(f"hairport: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    print(f"copied {report.blobs_copied} blobs ({report.blobs_present} already there) and "
          f"{sum(report.records.values())} records ({', '.join(f'{n} {k}' for k, n in sorted(report.records.items()))}) "
          f"from {settings.storage_dir}; indexed {indexed}")
    if report.missing_blobs:
        print(f"hairport: warning: {len(report.missing_blobs)} blobs that records name were not in the folder either "
              f"(first: {sorted(report.missing_blobs)[0]})", file=sys.stderr)
    return 0


def add_openapi(sub) -> None:
    p = sub.add_parser("openapi", help="print or write the OpenAPI contract of the HTTP API (YAML)")
    p.add_argument("--out", help="write here instead of standard output")
    p.set_defaults(run=cmd_openapi)


def openapi_yaml() -> str:
    """The API's OpenAPI document as YAML (what openapi.yaml holds)."""
    import yaml

    from hairport.service.app import create_app

    with tempfile.TemporaryDirectory(prefix="hairport-openapi-") as storage:  # the app needs a storage folder
        app = create_app(Settings(insecure_dev=True, storage_dir=storage), readiness=lambda: {},
                         queue_depths=lambda: {})
        return yaml.safe_dump(app.openapi(), sort_keys=False, allow_unicode=True)


def cmd_openapi(args: argparse.Namespace) -> int:
    text = openapi_yaml()
    if args.out:
        with OutputSet() as outputs:
            outputs.add(args.out, lambda path: path.write_text(text))
            outputs.commit()
    else:
        sys.stdout.write(text)
    return 0
