"""Saved experiments, assignments and submissions: one database, SQLite (the embedded default,
standard library ``sqlite3``, WAL mode) or PostgreSQL (``app/infra/store_postgres.py``) behind
one interface, ``Store``; ``app/infra/database.py`` opens the one a ``--database`` names.

An experiment is an exercise name, its parameter values and, for exercises
that take one, the uploaded recording (file name and bytes), under a readable code
(``app/infra/store_codes.py``).

Two kinds share the table: a tab's *autosave* (rewritten on every change,
debounced by the tab) and a *saved* snapshot (the Save button, or
``python -m app save``), which never changes.  Opening either code restores it.
Assignments and submissions are kept by ``app/infra/assignment_records.py``.

The schema has a version; opening a database applies the migrations it lacks
(``app/infra/schema.py``).

Durability: WAL with ``synchronous=NORMAL`` keeps every committed
transaction across a killed process (SIGKILL); only a power loss can drop
the newest commits.  Several server processes may share the file (WAL lets
readers and one writer work at once; writers wait up to ``BUSY_TIMEOUT_S``).
Recordings are stored once per content (SHA-256), so autosaving a tab with a
20 MB recording does not rewrite it.

Failures: every database error becomes a ``StoreUnavailable`` with one line saying what
is wrong (the disk is full, the file is damaged, it is another program's database), so a
caller can show it and carry on; a database whose tables have another layout is refused
when it is opened.  A server logs a failure once (``log_failures``) and once more when
writing works again, however many tabs retry meanwhile.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import sqlite3
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from app.infra import schema
from app.infra.assignment_records import AssignmentRecords
from app.infra.store_codes import (  # noqa: F401 - the names callers know from here
    CODE_ALPHABET,
    CODE_RANDOM_CHARS,
    StoreError,
    StoreUnavailable,
    code_prefix,
    new_code,
    normalise_code,
)

BUSY_TIMEOUT_S = 5.0
DATABASE_NAME = "lab.sqlite3"
COLUMNS = schema.COLUMNS


def describe(error: sqlite3.Error) -> str:
    """One line a student or an instructor can act on, for an SQLite error."""
    name = getattr(error, "sqlite_errorname", "")
    if name == "SQLITE_FULL":
        return "the disk holding the saved experiments is full"
    if name.startswith("SQLITE_IOERR"):
        return f"the saved experiments cannot be written ({error}: the disk may be full or failing)"
    if name in ("SQLITE_CORRUPT", "SQLITE_NOTADB"):
        return f"the saved-experiments database is damaged ({error})"
    if name.startswith(("SQLITE_BUSY", "SQLITE_LOCKED")):
        return "the saved-experiments database is busy (another program holds it locked)"
    if name.startswith(("SQLITE_READONLY", "SQLITE_CANTOPEN", "SQLITE_PERM")):
        return f"the saved-experiments database cannot be written ({error})"
    return f"the saved-experiments database failed ({error})"


@dataclass(frozen=True)
class Experiment:
    """One stored experiment.  ``parameters`` holds the values without ``data``;
    ``recording`` is the uploaded file's bytes (None: the exercise's default)."""

    code: str
    kind: str
    exercise: str
    parameters: dict
    recording_name: str | None = None
    recording: bytes | None = None
    updated: float = 0.0


def default_data_dir() -> Path:
    """``$XDG_DATA_HOME/amb-lab`` or ``~/.local/share/amb-lab``."""
    base = os.environ.get("XDG_DATA_HOME") or Path.home() / ".local" / "share"
    return Path(base) / "amb-lab"


class Store(AssignmentRecords):
    """The lab's database on SQLite; safe to share between threads of one process (one connection
    behind a lock) and between processes (WAL).  The SQL is written once, with ``?`` for values;
    ``PostgresStore`` changes only how it connects, runs statements and names failures."""

    dialect = "sqlite"
    database_errors: tuple[type[Exception], ...] = (sqlite3.Error,)

    def __init__(self, data_dir: Path | str | None = None, log_failures: bool = False):
        """Open (or create, or migrate) the database in ``data_dir``; ``StoreError`` if it cannot be
        used.  ``log_failures``: print the first failure (and the recovery) to stderr, as a server does."""
        self.log_failures = log_failures
        self.failing: str | None = None           # what went wrong last (None: the last access worked)
        directory = Path(data_dir) if data_dir is not None else default_data_dir()
        try:
            directory.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise StoreError(f"data directory {str(directory)!r}: {error.strerror}") from None
        self.path = directory / DATABASE_NAME
        self.where = str(self.path)               # what the server prints: the file, or the server
        self._lock = threading.Lock()
        deadline = time.monotonic() + BUSY_TIMEOUT_S
        while True:
            try:
                self._db = self._open()
                return
            except sqlite3.OperationalError as error:
                # Switching a new file to WAL takes an exclusive lock and SQLite does not wait
                # for it: several processes opening a fresh database at once retry here.
                if "locked" not in str(error) or time.monotonic() > deadline:
                    raise StoreUnavailable(f"database {self.where!r}: {describe(error)}") from None
                time.sleep(0.05)
            except sqlite3.Error as error:
                raise StoreUnavailable(f"database {self.where!r}: {describe(error)}") from None

    def _open(self) -> sqlite3.Connection:
        db = sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_S, check_same_thread=False,
                             isolation_level=None)   # explicit transactions below
        try:
            db.execute("PRAGMA journal_mode=WAL")
            db.execute("PRAGMA synchronous=NORMAL")
            db.execute("PRAGMA foreign_keys=ON")
            self._migrate(db)
        except BaseException:
            db.close()
            raise
        return db

    # -- what differs between SQLite and PostgreSQL ------------------------------------
    def _execute(self, db, statement: str, values: tuple = ()):
        """Run one statement (``?`` for each value); returns the cursor."""
        return db.execute(statement, values)

    def _transaction(self, db):
        return _Transaction(db)

    def _describe(self, error: Exception) -> str:
        return describe(error)

    def _table_columns(self, db, table: str) -> tuple[str, ...]:
        """The columns of ``table`` in order (empty: no such table)."""
        return tuple(row[1] for row in db.execute(f"PRAGMA table_info({table})"))

    def _version(self, db) -> int:
        """The schema version the database is at (in the file header: readable however
        damaged the pages of the tables are)."""
        return db.execute("PRAGMA user_version").fetchone()[0]

    def _set_version(self, db, version: int) -> None:
        db.execute(f"PRAGMA user_version={int(version)}")

    # -- the schema -----------------------------------------------------------------------
    def _migrate(self, db) -> None:
        """Bring the database to ``schema.VERSION`` (in one transaction, which also keeps other
        processes opening it at once from migrating twice); refuse another program's tables and
        a newer lab's schema."""
        with self._transaction(db):
            version = self._version(db)
            if version > schema.VERSION:
                raise StoreUnavailable(f"database {self.where!r} was made by a newer version of the lab "
                                       f"(schema {version}; this lab knows {schema.VERSION}): update the lab")
            self._refuse_foreign(db, present_only=True)
            if version < schema.VERSION:
                for statement in schema.statements(self.dialect, version):
                    self._execute(db, statement)
                self._set_version(db, schema.VERSION)
            self._refuse_foreign(db, present_only=False)

    def _refuse_foreign(self, db, present_only: bool) -> None:
        for table, columns in schema.COLUMNS.items():
            found = self._table_columns(db, table)
            if found != columns and (found or not present_only):
                raise StoreUnavailable(f"database {self.where!r} is not the lab's: its table {table!r} has "
                                       "another layout (choose another --data-dir or --database, or move it away)")

    @contextlib.contextmanager
    def _using(self, write: bool = False):
        """The connection, under the lock; a database error becomes one ``StoreUnavailable`` line
        (logged once per kind of failure when ``log_failures``).  ``write``: in a transaction."""
        with self._lock:
            try:
                db = self._connection()
                if write:
                    with self._transaction(db):
                        yield db
                else:
                    yield db
            except self.database_errors as error:
                reason = self._describe(error)
                if self.log_failures and reason != self.failing:
                    print(f"saved experiments: {reason}; tabs keep their settings and retry "
                          "(logged once until it works again)", file=sys.stderr, flush=True)
                self.failing = reason
                raise StoreUnavailable(reason) from None
            if write and self.failing is not None:     # reads work on a full disk: only a write tells
                if self.log_failures:
                    print("saved experiments: the database works again", file=sys.stderr, flush=True)
                self.failing = None

    def _connection(self):
        """The open connection (PostgreSQL: opened again after the server went away)."""
        return self._db

    def close(self) -> None:
        with self._lock:
            self._db.close()

    def insert_with_new_code(self, db, prefix: str, statement: str, values: tuple) -> str:
        """Run the INSERT ``statement`` (``... ON CONFLICT DO NOTHING``; its first value the code)
        with fresh codes until one is free; returns it."""
        for _ in range(100):
            code = new_code(prefix)
            if self._execute(db, statement, (code, *values)).rowcount == 1:
                return code
        raise StoreError(f"no free code left for the prefix {prefix}")

    # -- writing ------------------------------------------------------------------
    def save(self, exercise: str, parameters: dict, recording_name: str | None = None,
             recording: bytes | None = None) -> str:
        """A new saved (unchanging) experiment; returns its code."""
        return self._insert("saved", exercise, parameters, recording_name, recording)

    def new_autosave(self, exercise: str, parameters: dict, recording_name: str | None = None,
                     recording: bytes | None = None) -> str:
        """A new autosave slot for a tab; returns its code (update it with ``autosave``)."""
        return self._insert("autosave", exercise, parameters, recording_name, recording)

    def autosave(self, code: str, exercise: str, parameters: dict, recording_name: str | None = None,
                 recording: bytes | None = None) -> None:
        """Overwrite the autosave ``code`` (a saved snapshot is never overwritten)."""
        now = time.time()
        with self._using(write=True) as db:
            sha = self._put_recording(db, recording)
            cursor = self._execute(
                db, "UPDATE experiments SET exercise=?, parameters=?, recording_name=?, recording_sha256=?, "
                "updated=? WHERE code=? AND kind='autosave'",
                (exercise, encode(parameters), recording_name if sha else None, sha, now, code))
            if cursor.rowcount != 1:
                raise StoreError(f"{code} is not an autosave slot")

    def _insert(self, kind, exercise, parameters, recording_name, recording) -> str:
        now = time.time()
        with self._using(write=True) as db:
            sha = self._put_recording(db, recording)
            return self.insert_with_new_code(
                db, code_prefix(exercise),
                "INSERT INTO experiments VALUES (?, ?, ?, ?, ?, ?, ?, ?) ON CONFLICT DO NOTHING",
                (kind, exercise, encode(parameters), recording_name if sha else None, sha, now, now))

    def _put_recording(self, db, content: bytes | None) -> str | None:
        if content is None:
            return None
        sha = hashlib.sha256(content).hexdigest()
        self._execute(db, "INSERT INTO recordings VALUES (?, ?) ON CONFLICT DO NOTHING", (sha, content))
        return sha

    # -- reading ------------------------------------------------------------------
    def load(self, code: str) -> Experiment:
        """The experiment saved under ``code`` (typed in any case), or ``StoreError``."""
        code = normalise_code(code)
        with self._using() as db:
            row = self._execute(
                db, "SELECT e.code, e.kind, e.exercise, e.parameters, e.recording_name, r.content, e.updated "
                "FROM experiments e LEFT JOIN recordings r ON r.sha256 = e.recording_sha256 "
                "WHERE e.code = ?", (code,)).fetchone()
        if row is None:
            raise StoreError(f"no experiment is saved under {code}")
        try:
            parameters = json.loads(row[3])
        except ValueError:
            raise StoreUnavailable(f"the saved values of {code} are damaged") from None
        recording = bytes(row[5]) if row[5] is not None else None
        return Experiment(code=row[0], kind=row[1], exercise=row[2], parameters=parameters,
                          recording_name=row[4], recording=recording, updated=row[6])

    def count(self) -> int:
        with self._using() as db:
            return self._execute(db, "SELECT COUNT(*) FROM experiments").fetchone()[0]

    def check(self) -> str:
        """SQLite's integrity check ("ok" when the file is consistent)."""
        with self._using() as db:
            return db.execute("PRAGMA integrity_check").fetchone()[0]


class _Transaction:
    """BEGIN IMMEDIATE ... COMMIT (ROLLBACK on an exception)."""

    def __init__(self, db: sqlite3.Connection):
        self.db = db

    def __enter__(self):
        self.db.execute("BEGIN IMMEDIATE")

    def __exit__(self, kind, error, trace):
        if kind is None:
            self.db.execute("COMMIT")
        elif self.db.in_transaction:              # a full disk or an I/O error has rolled back already
            self.db.execute("ROLLBACK")
        return False


def encode(values: dict) -> str:
    """Parameter values as JSON (numpy scalars as plain numbers; ``data`` is not a parameter)."""
    plain = {name: (value.item() if hasattr(value, "item") else value)
             for name, value in values.items() if name != "data"}
    return json.dumps(plain, sort_keys=True)

