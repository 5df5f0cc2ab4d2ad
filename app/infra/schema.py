"""The lab's database schema, one for SQLite and PostgreSQL, with a version number and migrations.

``MIGRATIONS[k]`` takes a database from version ``k`` to ``k + 1``; a database records the
version it is at (SQLite: ``PRAGMA user_version`` in the file's header; PostgreSQL: the one
row of ``lab_schema``), and opening it applies the migrations it lacks in one transaction.
A database made by a newer lab (a higher version) is refused rather than written.  Files
made before versions existed hold the tables of version 1 at version 0: migration 1 creates
its tables only where they are missing, so they adopt it.

The statements are written once with ``{blob}``, ``{real}`` and ``{serial}`` for the types the
two dialects name differently (``DIALECTS``).  A migration that changes a table's columns
changes ``COLUMNS`` with it: a table whose columns differ is another program's, refused.
"""

from __future__ import annotations

DIALECTS = {
    "sqlite": {"blob": "BLOB", "real": "REAL", "serial": "INTEGER PRIMARY KEY"},
    "postgresql": {"blob": "BYTEA", "real": "DOUBLE PRECISION", "serial": "BIGSERIAL PRIMARY KEY"},
}

MIGRATIONS: tuple[tuple[str, ...], ...] = (
    # 1: saved experiments and their recordings (stored once per content)
    ("""CREATE TABLE IF NOT EXISTS recordings (
            sha256 TEXT PRIMARY KEY,
            content {blob} NOT NULL)""",
     """CREATE TABLE IF NOT EXISTS experiments (
            code TEXT PRIMARY KEY,
            kind TEXT NOT NULL CHECK (kind IN ('autosave', 'saved')),
            exercise TEXT NOT NULL,
            parameters TEXT NOT NULL,
            recording_name TEXT,
            recording_sha256 TEXT REFERENCES recordings(sha256),
            created {real} NOT NULL,
            updated {real} NOT NULL)"""),
    # 2: assignments (their definition as JSON), the students who opened one, their submissions
    ("""CREATE TABLE assignments (
            code TEXT PRIMARY KEY,
            definition TEXT NOT NULL,
            created {real} NOT NULL)""",
     """CREATE TABLE assignment_students (
            assignment TEXT NOT NULL REFERENCES assignments(code),
            student TEXT NOT NULL,
            joined {real} NOT NULL,
            PRIMARY KEY (assignment, student))""",
     """CREATE TABLE submissions (
            id {serial},
            assignment TEXT NOT NULL REFERENCES assignments(code),
            student TEXT NOT NULL,
            parameters TEXT NOT NULL,
            results TEXT NOT NULL,
            score {real} NOT NULL,
            submitted {real} NOT NULL)""",
     "CREATE INDEX submissions_by_student ON submissions (assignment, student)"),
)

VERSION = len(MIGRATIONS)

#: The columns of each table at ``VERSION``: another layout is not the lab's database.
COLUMNS = {"recordings": ("sha256", "content"),
           "experiments": ("code", "kind", "exercise", "parameters", "recording_name", "recording_sha256",
                           "created", "updated"),
           "assignments": ("code", "definition", "created"),
           "assignment_students": ("assignment", "student", "joined"),
           "submissions": ("id", "assignment", "student", "parameters", "results", "score", "submitted")}


def statements(dialect: str, from_version: int) -> list[str]:
    """The statements that take a database of ``dialect`` from ``from_version`` to ``VERSION``."""
    names = DIALECTS[dialect]
    return [statement.format(**names) for migration in MIGRATIONS[from_version:] for statement in migration]
