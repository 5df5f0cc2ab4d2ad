"""A throwaway PostgreSQL server for the tests: initdb and pg_ctl in a temporary directory, on
a free loopback port, as an unprivileged user when the tests run as root (initdb refuses root,
as on a CI machine).  The binaries are looked for on PATH, in $PG_BIN and in Debian's
/usr/lib/postgresql/<version>/bin."""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import socket
import subprocess
import tempfile
from pathlib import Path

UNPRIVILEGED_USER = "nobody"


def binaries() -> Path | None:
    """The directory holding initdb and pg_ctl, or None when PostgreSQL is not installed."""
    candidates = [os.environ.get("PG_BIN", "")]
    on_path = shutil.which("initdb")
    candidates.append(str(Path(on_path).parent) if on_path else "")
    candidates += sorted(glob.glob("/usr/lib/postgresql/*/bin"), reverse=True)
    for candidate in candidates:
        if candidate and (Path(candidate) / "initdb").is_file() and (Path(candidate) / "pg_ctl").is_file():
            return Path(candidate)
    return None


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


class PostgresServer:
    """Started by ``start``, stopped (and its directory removed) by ``stop``; ``new_database``
    gives every test a database of its own."""

    def __init__(self, bin_dir: Path):
        self.bin_dir = bin_dir
        self.directory = Path(tempfile.mkdtemp(prefix="lab-postgres-"))
        self.data = self.directory / "data"
        self.port = _free_port()
        self.as_root = os.geteuid() == 0
        self.user = UNPRIVILEGED_USER if self.as_root else pwd.getpwuid(os.geteuid()).pw_name
        self.databases = 0

    def _run(self, *command: str) -> None:
        prefix = ["runuser", "-u", UNPRIVILEGED_USER, "--"] if self.as_root else []
        subprocess.run(prefix + list(command), check=True, capture_output=True, timeout=120, cwd=self.directory)

    def start(self) -> PostgresServer:
        if self.as_root:
            entry = pwd.getpwnam(UNPRIVILEGED_USER)
            os.chown(self.directory, entry.pw_uid, entry.pw_gid)
        self._run(str(self.bin_dir / "initdb"), "-D", str(self.data), "-U", self.user, "--auth=trust",
                  "--no-sync", "-E", "UTF8")
        options = (f"-p {self.port} -c listen_addresses=127.0.0.1 -c unix_socket_directories='' "
                   "-c fsync=off -c full_page_writes=off")
        self._run(str(self.bin_dir / "pg_ctl"), "-D", str(self.data), "-l", str(self.directory / "log"),
                  "-o", options, "-w", "start")
        return self

    def url(self, database: str = "postgres") -> str:
        return f"postgresql://{self.user}@127.0.0.1:{self.port}/{database}"

    def new_database(self) -> str:
        """A fresh, empty database on the server; its URL."""
        import psycopg
        self.databases += 1
        name = f"lab_test_{self.databases}"
        with psycopg.connect(self.url(), autocommit=True) as db:
            db.execute(f"CREATE DATABASE {name}")
        return self.url(name)

    def stop(self) -> None:
        try:
            self._run(str(self.bin_dir / "pg_ctl"), "-D", str(self.data), "-m", "immediate", "stop")
        finally:
            shutil.rmtree(self.directory, ignore_errors=True)
