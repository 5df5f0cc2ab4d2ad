"""Shared fixtures of the browser tests: one lab server and one headless Chromium
(Debian's, driven by Playwright) for the whole test run."""

from __future__ import annotations

import os

import pytest

from app.commands.browser_bench import CHROMIUM, CHROMIUM_FLAGS, VIEWPORT
from app.commands.browser_bench import lab_server as serve_lab

browser_only = [pytest.mark.browser,
                pytest.mark.skipif(not os.path.exists(CHROMIUM), reason="Debian's chromium is not installed")]


@pytest.fixture(scope="session")
def lab_server(tmp_path_factory):
    """The lab served on a free port (new tabs open on kalman_noise); yields (url, server log path)."""
    log_path = tmp_path_factory.mktemp("lab-server") / "server.log"
    with serve_lab(log_path) as server:
        yield server.url, log_path


@pytest.fixture(scope="session")
def lab_url(lab_server) -> str:
    return lab_server[0]


@pytest.fixture(scope="session")
def browser():
    sync_api = pytest.importorskip("playwright.sync_api")
    with sync_api.sync_playwright() as p:
        chromium = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_FLAGS)
        yield chromium
        chromium.close()


class Tab:
    """A browser tab on the lab that records console and page errors."""

    def __init__(self, browser, url: str):
        self.page = browser.new_page(viewport=VIEWPORT)
        self.errors: list[str] = []
        self.page.on("console", lambda m: self.errors.append(m.text) if m.type == "error" else None)
        self.page.on("pageerror", lambda e: self.errors.append(str(e)))
        self.page.goto(url)

    def visible_input_values(self) -> list:
        return self.page.locator("input").evaluate_all(
            "els => els.map(e => (e.offsetParent !== null && e.type !== 'hidden') ? e.value : null)")

    def entry_box(self, label: str):
        """The box a value of the control labelled ``label`` is typed into: the row's own text box
        (a parameter without slider) or the one beside its slider (app/panels/entry.py)."""
        row = self.page.get_by_text(label, exact=True).locator("xpath=../../../..")
        own = row.locator("input.mantine-TextInput-input")
        return own if own.count() else row.locator("xpath=following-sibling::div[1]//input")

    def set_number(self, label: str, value: str) -> None:
        """Type ``value`` into the box of the control labelled ``label`` (read once typing stops)."""
        box = self.entry_box(label)
        box.fill(value)
        box.press("Enter")

    def switch_exercise(self, title: str, timeout_ms: float = 30000) -> None:
        """Choose ``title`` in the Exercise dropdown and wait for its heading."""
        self.page.get_by_label("Exercise", exact=True).first.click()
        self.page.get_by_role("option", name=title, exact=True).click()
        self.page.get_by_role("heading", name=title, exact=True).wait_for(timeout=timeout_ms)

    def open_panel_tab(self, name: str) -> None:
        self.page.get_by_role("tab", name=name).click()


@pytest.fixture
def open_tab(browser, lab_url):
    """Factory of lab tabs; closes them after the test."""
    tabs: list[Tab] = []

    def opener() -> Tab:
        tabs.append(Tab(browser, lab_url))
        return tabs[-1]

    yield opener
    for tab in tabs:
        tab.page.close()


# -- the store's two back ends ------------------------------------------------------------------
@pytest.fixture(scope="session")
def postgres_server():
    """A throwaway PostgreSQL server for the session (skipped only when PostgreSQL is not installed)."""
    from tests.postgres_server import PostgresServer, binaries
    bin_dir = binaries()
    if bin_dir is None:
        pytest.skip("PostgreSQL is not installed (no initdb/pg_ctl on PATH, $PG_BIN or /usr/lib/postgresql/*/bin)")
    pytest.importorskip("psycopg", reason="psycopg 3 is not installed (the test extras)")
    server = PostgresServer(bin_dir).start()
    yield server
    server.stop()


@pytest.fixture(params=["sqlite", "postgresql"])
def database(request, tmp_path):
    """Where a test's store lives, once per back end: (--data-dir, --database) for ``open_store``."""
    if request.param == "sqlite":
        return tmp_path, None
    return None, request.getfixturevalue("postgres_server").new_database()


@pytest.fixture
def open_test_store(database):
    """Opens the test's store (on either back end); every store it opened is closed afterwards."""
    from app.infra.database import open_store
    opened = []

    def opener(**options):
        store = open_store(database[1], database[0], **options)
        opened.append(store)
        return store
    yield opener
    for store in opened:
        store.close()


def pytest_unconfigure(config):
    """The run's last line, after pytest's own summary: what was skipped for a missing program and
    how to install it (``tests/skipped.py``)."""
    from tests.skipped import reason_of, summary_line
    reporter = config.pluginmanager.get_plugin("terminalreporter")
    if reporter is not None:
        line = summary_line([reason_of(report) for report in reporter.stats.get("skipped", [])])
        if line:
            reporter.write_line(line)
