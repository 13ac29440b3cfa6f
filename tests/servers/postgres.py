"""A PostgreSQL server of the tests' own: a fresh cluster (``initdb``) in a temporary folder, on a free port of
127.0.0.1, its unix socket in that folder, stopped and removed at the end. It never touches another cluster
(the machine's own may be running on 127.0.0.1:5432).

PostgreSQL's ``initdb`` and ``postgres`` refuse to run as root, and the tests run as root in CI: then every
PostgreSQL program runs as an unprivileged system user (``postgres`` if the machine has one, else ``nobody``)
that owns the temporary folder; otherwise they run as the tests' own user.

Under pytest-xdist each worker process starts its own server (its own folder and port): nothing is shared
between processes.
"""

from __future__ import annotations

import atexit
import os
import pwd
import re
import shutil
import stat
import subprocess
import tempfile
import time
from pathlib import Path

import psycopg
from psycopg import sql

from tests.conftest import free_port

#: the programs a server needs, all taken from one folder so that their versions match
PROGRAMS = ("initdb", "pg_ctl", "postgres")
#: where Debian's ``postgresql`` packages put the programs (off PATH): one folder per major version
DEBIAN_BINARIES = Path("/usr/lib/postgresql")
#: the system users that may run the server when the tests run as root, in order of preference
UNPRIVILEGED_USERS = ("postgres", "nobody")
#: the cluster's superuser: the same name whoever runs the server, so URLs do not depend on the machine
SUPERUSER = "hairport"
#: the database the URL names (created at start; ``postgres`` stays the maintenance database)
DATABASE = "hairport_test"
#: seconds for ``initdb`` (a few here; generous for a loaded CI machine)
INITDB_SECONDS = 120
#: seconds the server may take to accept connections after it was launched
START_SECONDS = 60
#: seconds ``pg_ctl stop -m fast`` may take before the server is killed
STOP_SECONDS = 30
#: seconds between two connection attempts while the server starts
POLL_SECONDS = 0.05
#: seconds one connection attempt may take while the server starts
CONNECT_TIMEOUT_SECONDS = 2
#: launches on another free port when the chosen one was taken meanwhile (another xdist worker, another test)
PORT_ATTEMPTS = 3
#: characters of the server's log quoted in an error
LOG_TAIL_CHARS = 3000
#: settings for a disposable test cluster, written to its postgresql.conf (restart keeps them)
TEST_SETTINGS = {
    # TCP on loopback only; the unix socket goes to the server's own folder (set at launch), never to
    # /var/run/postgresql where the machine's cluster keeps its socket and lock file
    "listen_addresses": "'127.0.0.1'",
    # no flush to disk: the cluster is thrown away, and only a crash of the whole machine could lose what a
    # crashed server had written (a killed server loses nothing: its writes are in the OS's page cache)
    "fsync": "off",
    # no full pages in the WAL after checkpoints: they only guard against torn pages of a machine crash
    "full_page_writes": "off",
    # synchronous_commit stays on: with fsync off a commit costs one write(), and a committed row then
    # survives a killed server, which the fault tests (a database stopped mid-job) rely on
    # little shared memory: several xdist workers each run a server, and test data is small
    "shared_buffers": "'32MB'",
    # no parallel query workers: fewer processes on a 2-core machine, and plans that do not vary with load
    "max_parallel_workers_per_gather": "0",
}
#: what the server logs when it could not listen on its port
PORT_TAKEN = re.compile(r"could not (bind|create any TCP/IP sockets)|Address already in use")


class PostgresUnavailable(RuntimeError):
    """The server could not be set up: no PostgreSQL programs, or initdb or the server failed."""


def find_binaries() -> Path:
    """The folder of ``initdb``, ``pg_ctl`` and ``postgres``: PATH first, then Debian's newest version.

    Returns
    -------
    Path
        The real folder (symbolic links resolved, e.g. /usr/local/bin/initdb -> /usr/lib/postgresql/15/bin/initdb):
        ``initdb`` and ``pg_ctl`` find ``postgres`` beside their own real path, so all three come from there.
    """
    on_path = shutil.which("initdb")
    if on_path:
        folder = Path(on_path).resolve().parent
        if all((folder / program).is_file() for program in PROGRAMS):
            return folder
    versions = sorted(DEBIAN_BINARIES.glob("*/bin"), key=_version_key, reverse=True)
    for folder in versions:
        if all((folder / program).is_file() for program in PROGRAMS):
            return folder
    raise PostgresUnavailable(
        f"the PostgreSQL tests need {', '.join(PROGRAMS)} (on PATH or in {DEBIAN_BINARIES}/VERSION/bin): "
        "tests/run installs Debian's postgresql package with apt-get")


def _version_key(folder: Path) -> tuple[int, ...]:
    """``/usr/lib/postgresql/15/bin`` -> (15,): numeric, so that 10 sorts after 9."""
    return tuple(int(part) for part in re.findall(r"\d+", folder.parent.name)) or (-1,)


def _server_user() -> pwd.struct_passwd | None:
    """The unprivileged user to run PostgreSQL as when the tests run as root, else None (run as ourselves)."""
    if os.geteuid() != 0:
        return None
    for name in UNPRIVILEGED_USERS:
        try:
            return pwd.getpwnam(name)
        except KeyError:
            continue
    raise PostgresUnavailable(f"the tests run as root and none of the users {UNPRIVILEGED_USERS} exists to run "
                              "PostgreSQL (initdb and postgres refuse root)")


def _reachable(folder: Path, user: pwd.struct_passwd) -> bool:
    """Whether ``user`` may pass through every folder from / down to ``folder`` (search permission)."""
    for step in [folder, *folder.parents]:
        mode = os.stat(step)
        if mode.st_uid == user.pw_uid:
            bit = stat.S_IXUSR
        elif mode.st_gid == user.pw_gid:
            bit = stat.S_IXGRP
        else:
            bit = stat.S_IXOTH
        if not mode.st_mode & bit:
            return False
    return True


def _make_folder(user: pwd.struct_passwd | None) -> Path:
    """A new temporary folder for the cluster, owned by the user that runs the server."""
    parent = Path(tempfile.gettempdir()).resolve()
    if user is not None and not _reachable(parent, user):
        parent = Path("/tmp")  # TMPDIR is private to root (pytest's own base folder is 0700, hence not used)
    folder = Path(tempfile.mkdtemp(prefix="hairport-pg-", dir=parent))
    if user is not None:
        os.chown(folder, user.pw_uid, user.pw_gid)
    return folder


class PostgresServer:
    """A PostgreSQL server in a temporary folder, on a free loopback port; ``with`` starts and removes it.

    Parameters
    ----------
    database : str
        The database created at start, the one ``url`` names.

    Attributes
    ----------
    url : str
        ``postgresql://hairport@127.0.0.1:PORT/DATABASE`` once started.
    port : int
        The TCP port, kept across ``restart``.
    folder : Path
        The temporary folder: ``data/`` (the cluster), the unix socket, ``postgres.log``.
    """

    def __init__(self, database: str = DATABASE):
        self.database = database
        self.binaries = find_binaries()
        self.user = _server_user()
        self.folder: Path | None = None
        self.port: int | None = None
        self.process: subprocess.Popen | None = None
        self._log = None

    # ---------------------------------------------------------------- public
    @property
    def url(self) -> str:
        return f"postgresql://{SUPERUSER}@127.0.0.1:{self.port}/{self.database}"

    @property
    def admin_url(self) -> str:
        """The maintenance database's URL (the one to create or drop databases from)."""
        return f"postgresql://{SUPERUSER}@127.0.0.1:{self.port}/postgres"

    @property
    def log_path(self) -> Path:
        return self.folder / "postgres.log"

    def start(self) -> str:
        """Create the cluster, start the server on a free port, create the database; return its URL."""
        self.folder = _make_folder(self.user)
        atexit.register(self.close)  # a backstop for callers that neither use ``with`` nor close()
        self._initdb()
        for attempt in range(PORT_ATTEMPTS):
            self.port = free_port()
            if self._launch(retry_port=attempt + 1 < PORT_ATTEMPTS):
                break
        with psycopg.connect(self.admin_url, autocommit=True) as connection:
            connection.execute(sql.SQL("CREATE DATABASE {}").format(sql.Identifier(self.database)))
        return self.url

    def stop(self) -> None:
        """Stop the server (``pg_ctl stop -m fast``: open sessions are ended, a checkpoint is written), killing it
        if it does not stop in time. The cluster stays: ``start_again`` / ``restart`` bring it back."""
        if self.process is None:
            return
        if self.process.poll() is None:
            try:
                self._run("pg_ctl", "stop", "-D", str(self.folder / "data"), "-m", "fast", "-w", "-t",
                          str(STOP_SECONDS), timeout=STOP_SECONDS + 5, check=False)
                self.process.wait(timeout=STOP_SECONDS)
            except subprocess.TimeoutExpired:  # pg_ctl or the server hung: the kill below ends it either way
                self.process.kill()
                self.process.wait()
        self.process = None
        self._log.close()

    def start_again(self) -> None:
        """Start the stopped server on the same port and cluster (what it committed is there again)."""
        self._launch(retry_port=False)

    def restart(self) -> None:
        """Stop the server and start it again on the same port and cluster: what a database restarted mid-job
        looks like to the application (open connections break, committed rows stay)."""
        self.stop()
        self.start_again()

    def close(self) -> None:
        """Stop the server and remove its folder."""
        atexit.unregister(self.close)
        self.stop()
        if self.folder is not None:
            shutil.rmtree(self.folder)
            self.folder = None

    def __enter__(self) -> PostgresServer:
        try:
            self.start()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ---------------------------------------------------------------- steps
    def _initdb(self) -> None:
        # trust: any local user may connect as any role, acceptable for a throw-away cluster that listens on
        # loopback only; --no-sync: no final flush of the ~40 MB cluster (0.07 s of 0.6 s here, more on a slow
        # disk); --locale=C: the same sorting on every machine, whatever locales it has
        self._run("initdb", "-D", str(self.folder / "data"), "-U", SUPERUSER, "--auth=trust", "--encoding=UTF8",
                  "--locale=C", "--no-sync", timeout=INITDB_SECONDS)
        with open(self.folder / "data" / "postgresql.conf", "a") as conf:
            conf.write("\n# hairport's test settings (tests/servers/postgres.py)\n")
            conf.writelines(f"{name} = {value}\n" for name, value in TEST_SETTINGS.items())

    def _launch(self, retry_port: bool) -> bool:
        """Run ``postgres`` on ``self.port`` and wait until it accepts connections.

        Returns False when the port was taken meanwhile and ``retry_port`` allows another; raises otherwise."""
        self._log = open(self.log_path, "ab")
        # postgres itself (not pg_ctl start) as our child: its exit is seen at once while waiting, and a new
        # session keeps a terminal's Ctrl-C for pytest, which then stops the server in order
        self.process = subprocess.Popen(
            [str(self.binaries / "postgres"), "-D", str(self.folder / "data"), "-p", str(self.port),
             "-k", str(self.folder)],
            stdin=subprocess.DEVNULL, stdout=self._log, stderr=subprocess.STDOUT, start_new_session=True,
            **self._as_owner())
        deadline = time.monotonic() + START_SECONDS
        while True:
            try:
                psycopg.connect(self.admin_url, connect_timeout=CONNECT_TIMEOUT_SECONDS).close()
                return True
            except psycopg.OperationalError:  # refused, or "the database system is starting up"
                pass
            if self.process.poll() is not None:
                self.process = None
                self._log.close()
                if retry_port and PORT_TAKEN.search(self._log_tail()):
                    return False
                raise PostgresUnavailable(f"postgres exited at start on port {self.port}:\n{self._log_tail()}")
            if time.monotonic() > deadline:
                self.stop()
                raise PostgresUnavailable(
                    f"postgres did not accept connections on port {self.port} within {START_SECONDS} s:\n"
                    f"{self._log_tail()}")
            time.sleep(POLL_SECONDS)

    # ---------------------------------------------------------------- helpers
    def _as_owner(self) -> dict:
        """subprocess arguments that run a PostgreSQL program as the folder's owner: as root, the unprivileged
        user with no supplementary groups (``setpriv --reuid --regid --clear-groups``); else ourselves. The
        working folder is the server's own, which that user can enter (initdb and pg_ctl look up theirs)."""
        owner = {"cwd": self.folder, "env": {k: v for k, v in os.environ.items() if not k.startswith("PG")}}
        if self.user is not None:
            owner.update(user=self.user.pw_uid, group=self.user.pw_gid, extra_groups=[])
        return owner

    def _run(self, program: str, *args: str, timeout: float, check: bool = True) -> subprocess.CompletedProcess:
        done = subprocess.run([str(self.binaries / program), *args], stdin=subprocess.DEVNULL, capture_output=True,
                              text=True, timeout=timeout, **self._as_owner())
        if check and done.returncode != 0:
            raise PostgresUnavailable(f"{program} failed ({done.returncode}):\n{done.stdout}{done.stderr}")
        return done

    def _log_tail(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")[-LOG_TAIL_CHARS:]
        except OSError as error:
            return f"(no log: {error})"
