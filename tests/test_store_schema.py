"""The store's schema version and migrations (app/infra/schema.py) and --database, on SQLite and
PostgreSQL (a throwaway server, tests/postgres_server.py)."""

from __future__ import annotations

import sqlite3
import subprocess
import sys
import time

import pytest

from app.cli import main
from app.infra import schema
from app.infra.database import check_database, open_store
from app.infra.store import StoreError, StoreUnavailable


def _version(database) -> int:
    data_dir, url = database
    if url is None:
        with sqlite3.connect(data_dir / "lab.sqlite3") as db:
            return db.execute("PRAGMA user_version").fetchone()[0]
    import psycopg
    with psycopg.connect(url) as db:
        return db.execute("SELECT version FROM lab_schema").fetchone()[0]


def _set_version(database, version: int) -> None:
    data_dir, url = database
    if url is None:
        with sqlite3.connect(data_dir / "lab.sqlite3") as db:
            db.execute(f"PRAGMA user_version={version}")
        return
    import psycopg
    with psycopg.connect(url) as db:
        db.execute("UPDATE lab_schema SET version = %s", (version,))


def test_a_new_database_is_at_the_newest_version_and_reopens_unchanged(open_test_store, database):
    store = open_test_store()
    code = store.save("kalman_noise", {"seed": 7})
    assert _version(database) == schema.VERSION == len(schema.MIGRATIONS)
    again = open_test_store()
    assert again.load(code).parameters == {"seed": 7} and again.count() == 1 and again.check() == "ok"


def test_a_database_of_a_newer_lab_is_refused(open_test_store, database):
    open_test_store().close()
    _set_version(database, schema.VERSION + 1)
    with pytest.raises(StoreUnavailable, match=f"newer version of the lab \\(schema {schema.VERSION + 1}"):
        open_test_store()


def test_a_file_made_before_versions_is_migrated_keeping_its_experiments(tmp_path):
    """A version-0 file (the tables of migration 1, no version) gets the assignment tables and
    keeps every experiment."""
    with sqlite3.connect(tmp_path / "lab.sqlite3") as db:
        for statement in schema.MIGRATIONS[0]:
            db.execute(statement.format(**schema.DIALECTS["sqlite"]))
        db.execute("INSERT INTO experiments VALUES ('KN-7Q3M', 'saved', 'kalman_noise', '{\"seed\": 4}', NULL, "
                   "NULL, 0, 0)")
    from app.infra.store import Store
    store = Store(tmp_path)
    assert store.load("KN-7Q3M").parameters == {"seed": 4}
    assert _version((tmp_path, None)) == schema.VERSION
    code = store.create_assignment("KN", {"title": "t"})
    assert store.assignment(code) == (code, {"title": "t"})


OPEN_FRESH = """
import sys, time
from app.infra.database import open_store
time.sleep(max(0.0, float(sys.argv[3]) - time.time()))    # all processes open at the same instant
open_store(sys.argv[2] or None, sys.argv[1]).save("kalman_noise", {})
"""


def test_processes_migrating_one_database_at_once(open_test_store, database):
    """Lab processes on several machines start together on a new database: one migrates it, the
    others wait for that and find it done."""
    start = time.time() + 2.0
    processes = [subprocess.Popen([sys.executable, "-c", OPEN_FRESH, str(database[0] or ""), database[1] or "",
                                   str(start)], stderr=subprocess.PIPE, text=True) for _ in range(4)]
    errors = [p.communicate(timeout=60)[1] for p in processes]
    assert [p.returncode for p in processes] == [0] * 4, errors
    assert open_test_store().count() == 4 and _version(database) == schema.VERSION


def test_database_urls_are_checked():
    assert check_database("postgresql://lab:secret@db.example:5432/lab") == "postgresql://lab:secret@db.example:5432/lab"
    for bad in ("mysql://x/y", "postgresql://host-without-database", "lab.sqlite3"):
        with pytest.raises(StoreError, match="not a PostgreSQL URL: expected postgresql://"):
            check_database(bad)


def test_save_and_run_share_a_database(database, capsys):
    data_dir, url = database
    where = ["--database", url] if url else ["--data-dir", str(data_dir)]
    assert main(["save", "ekf_disturbance", "--set", "filter_q_force=2", *where]) == 0
    code = capsys.readouterr().out.strip()
    assert open_store(url, data_dir).load(code).parameters["filter_q_force"] == 2
    assert main(["run", "--code", code, "--duration", "0.1", "--json", *where]) == 0
    assert f'"code": "{code}"' in capsys.readouterr().out


def test_an_unreachable_or_malformed_database_is_one_line(capsys):
    assert main(["save", "kalman_noise", "--database", "postgresql://lab@127.0.0.1:1/lab"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: database postgresql://lab@127.0.0.1:1/lab: the PostgreSQL server") \
        and err.count("\n") == 1
    assert main(["serve", "--database", "sqlite:///x", "--port", "8081"]) == 2
    assert "not a PostgreSQL URL" in capsys.readouterr().err


def test_a_dropped_postgresql_connection_is_one_line_then_opened_again(postgres_server):
    """The server restarts (here: the lab's connection is ended from outside): one access fails
    with one line, the next one connects again and works."""
    import psycopg
    url = postgres_server.new_database()
    store = open_store(url)
    code = store.save("kalman_noise", {"seed": 1})
    with psycopg.connect(url, autocommit=True) as admin:
        admin.execute("SELECT pg_terminate_backend(pid) FROM pg_stat_activity WHERE datname = current_database() "
                      "AND pid <> pg_backend_pid()")
    with pytest.raises(StoreUnavailable, match="^the PostgreSQL server of the saved experiments cannot be reached"):
        store.load(code)
    assert store.load(code).parameters == {"seed": 1}
    store.close()
