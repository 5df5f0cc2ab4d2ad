"""The lab's database on a PostgreSQL server (psycopg 3): every lab process on every machine of
a lecture hall shares its experiments, assignments and submissions.

The same SQL as on SQLite (``app/infra/store.py``); this class changes only how the store
connects (one connection per process, behind the store's lock, opened again when the server
went away), how a statement is run (``%s`` for each value), how the schema version is kept
(the one row of ``lab_schema``; a transaction-wide advisory lock keeps processes opening a new
database at once from migrating it twice) and how a failure is named."""

from __future__ import annotations

import threading
from urllib.parse import urlsplit

from app.infra.store import Store
from app.infra.store_codes import StoreError, StoreUnavailable

try:
    import psycopg
except ImportError:                 # the lab without the ``postgres`` extra: SQLite only
    psycopg = None

CONNECT_TIMEOUT_S = 5
MIGRATION_LOCK = 0x414D424C         # "AMBL": the advisory lock that serialises migrations
POSTGRES_SCHEMES = ("postgresql", "postgres")


def shown_url(url: str) -> str:
    """The database's address without its password (what the server prints)."""
    parts = urlsplit(url)
    host = parts.hostname or "localhost"
    user = f"{parts.username}@" if parts.username else ""
    port = f":{parts.port}" if parts.port else ""
    return f"{parts.scheme}://{user}{host}{port}{parts.path}"


def describe(error: Exception) -> str:
    """One line an instructor can act on, for a psycopg error."""
    text = " ".join(str(error).split())[:200]
    if isinstance(error, psycopg.OperationalError):
        return f"the PostgreSQL server of the saved experiments cannot be reached ({text})"
    if isinstance(error, psycopg.errors.DiskFull):
        return "the disk holding the saved experiments is full"
    if isinstance(error, psycopg.errors.InsufficientPrivilege):
        return f"the saved-experiments database cannot be written ({text})"
    return f"the saved-experiments database failed ({text})"


class PostgresStore(Store):
    """``Store`` on a PostgreSQL server named by a ``postgresql://USER:PASSWORD@HOST:PORT/DB`` URL."""

    dialect = "postgresql"

    def __init__(self, url: str, log_failures: bool = False):
        if psycopg is None:
            raise StoreError("--database postgresql://... needs psycopg 3: pip install 'psycopg[binary]>=3.1' "
                             "(the lab's 'postgres' extra)")
        self.database_errors = (psycopg.Error,)
        self.log_failures = log_failures
        self.failing: str | None = None
        self.url, self.path, self.where = url, None, shown_url(url)
        self._lock = threading.Lock()
        try:
            self._db = self._open()
        except psycopg.Error as error:
            raise StoreUnavailable(f"database {self.where}: {describe(error)}") from None

    def _open(self):
        db = psycopg.connect(self.url, autocommit=True, connect_timeout=CONNECT_TIMEOUT_S)
        try:
            self._migrate(db)
        except BaseException:
            db.close()
            raise
        return db

    def _connection(self):
        if self._db.closed or self._db.broken:   # the server restarted: connect again
            self._db.close()
            self._db = self._open()
        return self._db

    def _execute(self, db, statement: str, values: tuple = ()):
        return db.execute(statement.replace("?", "%s"), values)

    def _transaction(self, db):
        return db.transaction()

    def _describe(self, error: Exception) -> str:
        return describe(error)

    def _table_columns(self, db, table: str) -> tuple[str, ...]:
        rows = db.execute("SELECT column_name FROM information_schema.columns WHERE table_schema = "
                          "current_schema() AND table_name = %s ORDER BY ordinal_position", (table,)).fetchall()
        return tuple(row[0] for row in rows)

    def _version(self, db) -> int:
        db.execute("SELECT pg_advisory_xact_lock(%s)", (MIGRATION_LOCK,))
        db.execute("CREATE TABLE IF NOT EXISTS lab_schema (version INTEGER NOT NULL)")
        row = db.execute("SELECT version FROM lab_schema").fetchone()
        return row[0] if row is not None else 0

    def _set_version(self, db, version: int) -> None:
        db.execute("DELETE FROM lab_schema")
        db.execute("INSERT INTO lab_schema VALUES (%s)", (version,))

    def check(self) -> str:
        """"ok" when the server answers and holds the lab's tables."""
        with self._using() as db:
            self._refuse_foreign(db, present_only=False)
        return "ok"
