"""Which database a lab process uses: ``--database postgresql://...`` (a PostgreSQL server the
whole lecture hall shares), else the SQLite file in ``--data-dir`` (the embedded default)."""

from __future__ import annotations

from pathlib import Path
from urllib.parse import urlsplit

from app.infra.store import Store
from app.infra.store_codes import StoreError
from app.infra.store_postgres import POSTGRES_SCHEMES, PostgresStore

#: ``--database`` from the environment: a URL with a password stays out of the process list.
DATABASE_VARIABLE = "AMB_LAB_DATABASE"


def chosen_database(flag: str | None, environment) -> str | None:
    """``--database`` if given, else ``$AMB_LAB_DATABASE`` (None: SQLite), checked."""
    return check_database(flag if flag is not None else environment.get(DATABASE_VARIABLE) or None)


def check_database(url: str | None) -> str | None:
    """A ``--database`` URL as given, or ``StoreError`` naming the form expected."""
    if url is None:
        return None
    if urlsplit(url).scheme not in POSTGRES_SCHEMES or not urlsplit(url).path.strip("/"):
        raise StoreError(f"--database {url[:60]!r} is not a PostgreSQL URL: expected "
                         "postgresql://USER:PASSWORD@HOST:PORT/DATABASE (leave it out for SQLite in --data-dir)")
    return url


def open_store(database: str | None, data_dir: Path | str | None = None, log_failures: bool = False) -> Store:
    """The store ``--database`` names (PostgreSQL), else SQLite in ``data_dir``; ``StoreError``."""
    url = check_database(database)
    if url is not None:
        return PostgresStore(url, log_failures)
    return Store(data_dir, log_failures)
