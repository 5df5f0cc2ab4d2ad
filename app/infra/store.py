"""Saved experiments: one SQLite file (standard library ``sqlite3``, WAL mode).

An experiment is an exercise name, its parameter values and, for exercises
that take one, the uploaded recording (file name and bytes).  Each has a
readable code such as ``KN-7Q3M-X9TA-HPRW``: two letters from the exercise
name, then twelve random characters without look-alikes such as 0/O and 1/I,
about 59 bits, so that guessing codes is hopeless.  Codes of the older form,
four random characters (``KN-7Q3M``), keep opening.

Two kinds share the table: a tab's *autosave* (rewritten on every change,
debounced by the tab) and a *saved* snapshot (the Save button, or
``python -m app save``), which never changes.  Opening either code restores it.

Durability: WAL with ``synchronous=NORMAL`` keeps every committed
transaction across a killed process (SIGKILL); only a power loss can drop
the newest commits.  Several server processes may share the file (WAL lets
readers and one writer work at once; writers wait up to ``BUSY_TIMEOUT_S``).
Recordings are stored once per content (SHA-256), so autosaving a tab with a
20 MB recording does not rewrite it.

Failures: every SQLite error becomes a ``StoreUnavailable`` with one line saying what
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
import secrets
import sqlite3
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

#: Characters of the random part of a code: no 0/O, 1/I/L look-alikes.
CODE_ALPHABET = "ABCDEFGHJKMNPQRSTUVWXYZ23456789"
CODE_RANDOM_CHARS = 12            # 12 × log2(31) = 59 bits, written in groups of four
CODE_GROUP = 4
OLD_CODE_RANDOM_CHARS = 4         # codes made before: still accepted
BUSY_TIMEOUT_S = 5.0
DATABASE_NAME = "lab.sqlite3"

SCHEMA = """
CREATE TABLE IF NOT EXISTS recordings (
    sha256 TEXT PRIMARY KEY,
    content BLOB NOT NULL
);
CREATE TABLE IF NOT EXISTS experiments (
    code TEXT PRIMARY KEY,
    kind TEXT NOT NULL CHECK (kind IN ('autosave', 'saved')),
    exercise TEXT NOT NULL,
    parameters TEXT NOT NULL,
    recording_name TEXT,
    recording_sha256 TEXT REFERENCES recordings(sha256),
    created REAL NOT NULL,
    updated REAL NOT NULL
);
"""


#: The columns of each table, as ``SCHEMA`` makes them: another layout is not the lab's database.
COLUMNS = {"recordings": ("sha256", "content"),
           "experiments": ("code", "kind", "exercise", "parameters", "recording_name", "recording_sha256",
                           "created", "updated")}


class StoreError(ValueError):
    """A code is malformed or unknown, or the database cannot be used (one line)."""


class StoreUnavailable(StoreError):
    """The database cannot be read or written now (full disk, damaged file, another layout):
    a tab keeps its settings and tries again later."""


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


def code_prefix(exercise: str) -> str:
    """Two letters from the exercise name: its first and last word's initials
    (``kalman_noise`` -> ``KN``, ``lqg_vs_pid`` -> ``LP``)."""
    words = [w for w in exercise.split("_") if w] or ["X"]
    return (words[0][0] + (words[-1][0] if len(words) > 1 else words[0][-1])).upper()


def grouped(prefix: str, random_part: str) -> str:
    """A code as stored and shown: the prefix, then the random part in groups of ``CODE_GROUP``."""
    groups = [random_part[k:k + CODE_GROUP] for k in range(0, len(random_part), CODE_GROUP)]
    return "-".join([prefix, *groups])


def normalise_code(text: str) -> str:
    """A code as typed (any case, spaces, dashes or none) in its stored form, or ``StoreError``; a code
    of the right shape with characters no code holds names them (issue 25: "ZZ-0000")."""
    compact = "".join(str(text).split()).upper().replace("_", "").replace("-", "")
    prefix, rest = compact[:2], compact[2:]
    shown = str(text).strip()[:40]
    if not (len(prefix) == 2 and prefix.isascii() and prefix.isalpha()
            and len(rest) in (CODE_RANDOM_CHARS, OLD_CODE_RANDOM_CHARS)):
        raise StoreError(f"{shown!r} is not an experiment code: expected two letters and {CODE_RANDOM_CHARS} "
                         f"characters, e.g. KN-7Q3M-X9TA-HPRW (older codes: KN-7Q3M)")
    foreign = sorted(set(rest) - set(CODE_ALPHABET))
    if foreign:                           # the right shape, but characters a code never holds
        left_out = sorted(set("0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZ") - set(CODE_ALPHABET))
        raise StoreError(f"{shown!r} is not an experiment code: codes never contain {', '.join(foreign)} "
                         f"({', '.join(left_out[:-1])} and {left_out[-1]} look alike and are left out)")
    return grouped(prefix, rest)


class Store:
    """The experiments database; safe to share between threads of one process
    (one connection behind a lock) and between processes (WAL)."""

    def __init__(self, data_dir: Path | str | None = None, log_failures: bool = False):
        """Open (or create) the database in ``data_dir``; ``StoreError`` if it cannot be used.
        ``log_failures``: print the first failure (and the recovery) to stderr, as a server does."""
        self.log_failures = log_failures
        self.failing: str | None = None           # what went wrong last (None: the last access worked)
        directory = Path(data_dir) if data_dir is not None else default_data_dir()
        try:
            directory.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise StoreError(f"data directory {str(directory)!r}: {error.strerror}") from None
        self.path = directory / DATABASE_NAME
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
                    raise StoreUnavailable(f"database {str(self.path)!r}: {describe(error)}") from None
                time.sleep(0.05)
            except sqlite3.Error as error:
                raise StoreUnavailable(f"database {str(self.path)!r}: {describe(error)}") from None

    def _open(self) -> sqlite3.Connection:
        db = sqlite3.connect(self.path, timeout=BUSY_TIMEOUT_S, check_same_thread=False,
                             isolation_level=None)   # explicit transactions below
        try:
            db.execute("PRAGMA journal_mode=WAL")
            db.execute("PRAGMA synchronous=NORMAL")
            db.execute("PRAGMA foreign_keys=ON")
            db.executescript(SCHEMA)
            foreign = [table for table, columns in COLUMNS.items()
                       if tuple(row[1] for row in db.execute(f"PRAGMA table_info({table})")) != columns]
        except sqlite3.Error:
            db.close()
            raise
        if foreign:
            db.close()
            raise StoreUnavailable(f"database {str(self.path)!r} is not the lab's: its table {foreign[0]!r} has "
                                   "another layout (choose another --data-dir, or move the file away)")
        return db

    @contextlib.contextmanager
    def _using(self, write: bool = False):
        """The connection, under the lock; an SQLite error becomes one ``StoreUnavailable`` line
        (logged once per kind of failure when ``log_failures``).  ``write``: in a transaction."""
        with self._lock:
            try:
                if write:
                    with _Transaction(self._db):
                        yield self._db
                else:
                    yield self._db
            except sqlite3.Error as error:
                reason = describe(error)
                if self.log_failures and reason != self.failing:
                    print(f"saved experiments: {reason}; tabs keep their settings and retry "
                          "(logged once until it works again)", file=sys.stderr, flush=True)
                self.failing = reason
                raise StoreUnavailable(reason) from None
            if write and self.failing is not None:     # reads work on a full disk: only a write tells
                if self.log_failures:
                    print("saved experiments: the database works again", file=sys.stderr, flush=True)
                self.failing = None

    def close(self) -> None:
        with self._lock:
            self._db.close()

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
            sha = self._put_recording(recording)
            cursor = db.execute(
                "UPDATE experiments SET exercise=?, parameters=?, recording_name=?, recording_sha256=?, "
                "updated=? WHERE code=? AND kind='autosave'",
                (exercise, _encode(parameters), recording_name if sha else None, sha, now, code))
            if cursor.rowcount != 1:
                raise StoreError(f"{code} is not an autosave slot")

    def _insert(self, kind, exercise, parameters, recording_name, recording) -> str:
        now = time.time()
        text = _encode(parameters)
        with self._using(write=True) as db:
            sha = self._put_recording(recording)
            for _ in range(100):
                code = grouped(code_prefix(exercise),
                               "".join(secrets.choice(CODE_ALPHABET) for _ in range(CODE_RANDOM_CHARS)))
                try:
                    db.execute(
                        "INSERT INTO experiments VALUES (?, ?, ?, ?, ?, ?, ?, ?)",
                        (code, kind, exercise, text, recording_name if sha else None, sha, now, now))
                    return code
                except sqlite3.IntegrityError:   # the code is taken: draw another
                    continue
        raise StoreError(f"no free experiment code left for {exercise!r}")

    def _put_recording(self, content: bytes | None) -> str | None:
        if content is None:
            return None
        sha = hashlib.sha256(content).hexdigest()
        self._db.execute("INSERT OR IGNORE INTO recordings VALUES (?, ?)", (sha, content))
        return sha

    # -- reading ------------------------------------------------------------------
    def load(self, code: str) -> Experiment:
        """The experiment saved under ``code`` (typed in any case), or ``StoreError``."""
        code = normalise_code(code)
        with self._using() as db:
            row = db.execute(
                "SELECT e.code, e.kind, e.exercise, e.parameters, e.recording_name, r.content, e.updated "
                "FROM experiments e LEFT JOIN recordings r ON r.sha256 = e.recording_sha256 "
                "WHERE e.code = ?", (code,)).fetchone()
        if row is None:
            raise StoreError(f"no experiment is saved under {code}")
        try:
            parameters = json.loads(row[3])
        except ValueError:
            raise StoreUnavailable(f"the saved values of {code} are damaged") from None
        return Experiment(code=row[0], kind=row[1], exercise=row[2], parameters=parameters,
                          recording_name=row[4], recording=row[5], updated=row[6])

    def count(self) -> int:
        with self._using() as db:
            return db.execute("SELECT COUNT(*) FROM experiments").fetchone()[0]

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


def _encode(parameters: dict) -> str:
    """Parameter values as JSON (numpy scalars as plain numbers; ``data`` is not a parameter)."""
    plain = {name: (value.item() if hasattr(value, "item") else value)
             for name, value in parameters.items() if name != "data"}
    return json.dumps(plain, sort_keys=True)
