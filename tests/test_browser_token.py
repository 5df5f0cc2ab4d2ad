"""The class token and the Origin check in a real browser (issue 12): a lab started with a
token shows a new tab one field and builds nothing before the right token is entered; with
it the lab works; a page from another origin cannot open a websocket to the lab."""

from __future__ import annotations

import contextlib
import http.server
import json
import subprocess
import sys
import threading
import time

import msgspec
import pytest

from app.commands.browser_bench import ROOT, VIEWPORT, free_port
from app.commands.lab_processes import wait_http
from app.commands.load_bench import PROTOCOL
from tests.conftest import browser_only
from tests.wsclient import CAMERA

pytestmark = browser_only
TOKEN = "kalman42"
READOUT = "RMS displacement, measured feedback"
#: A page of another site that tries to open a lab tab the way viser's client does (a camera
#: message first: viser builds a tab after it) and records what its websocket saw.
FOREIGN_PAGE = """<!doctype html><title>not the lab</title><script>
window.seen = {opened: false, messages: 0, closed: null};
const ws = new WebSocket("WS_URL", "PROTOCOL");
ws.onopen = () => { window.seen.opened = true; ws.send(new Uint8Array(CAMERA_BYTES)); };
ws.onmessage = () => { window.seen.messages += 1; };
ws.onclose = (e) => { window.seen.closed = e.code; };
</script>"""


def _lab_shown(page) -> bool:
    return any(page.get_by_text(text).count() for text in (READOUT, "Rotor position", "Exercise"))


@contextlib.contextmanager
def _page_server(html: str):
    """``html`` served at http://127.0.0.1:PORT/ by a thread; yields that address."""
    class Page(http.server.BaseHTTPRequestHandler):
        def do_GET(self):
            body = html.encode()
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args):
            pass
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Page)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_address[1]}"
    finally:
        server.shutdown()
        server.server_close()


@contextlib.contextmanager
def _lab_with_token(tmp_path):
    port = free_port()
    log = tmp_path / "server.log"
    with log.open("w") as out:
        server = subprocess.Popen([sys.executable, "-m", "app", "--port", str(port), "--token", TOKEN,
                                   "--data-dir", str(tmp_path / "data")], cwd=ROOT, stdout=out,
                                  stderr=subprocess.STDOUT, text=True)
        try:
            wait_http(f"http://127.0.0.1:{port}", server, 120.0, log)
            yield port, log
        finally:
            server.terminate()
            server.wait(timeout=10)


@pytest.fixture
def page_factory(browser):
    """New pages of the suite's one browser (a second Playwright would clash with its event loop)."""
    pages = []

    def new_page():
        page = browser.new_page(viewport=VIEWPORT)
        page.errors = []
        page.on("pageerror", lambda e: page.errors.append(str(e)))
        pages.append(page)
        return page
    yield new_page
    for page in pages:
        page.close()


def test_token_gate_and_foreign_origin(tmp_path, page_factory):
    with _lab_with_token(tmp_path) as (port, log):
        page = page_factory()
        page.goto(f"http://127.0.0.1:{port}")
        page.get_by_text("Class token", exact=True).wait_for(timeout=60000)
        field = page.get_by_text("Class token", exact=True).locator("xpath=../../..").locator("input:visible").last
        enter = page.get_by_role("button", name="Enter the lab")
        time.sleep(3.0)                               # time enough to build a lab, if it were built
        assert not _lab_shown(page)
        page.screenshot(path=str(tmp_path / "token_field.png"))

        field.fill("not-it")
        enter.click()
        page.get_by_text("4 tries left").wait_for(timeout=20000)
        assert not _lab_shown(page)

        field.fill("")
        field.press_sequentially(TOKEN, delay=150)    # typed by hand: the keystrokes are not tries
        time.sleep(1.5)
        assert not _lab_shown(page) and page.get_by_text("4 tries left").count() == 1
        enter.click()
        page.get_by_text(READOUT).first.wait_for(timeout=60000)
        page.get_by_label("Exercise", exact=True).first.wait_for(timeout=10000)
        assert page.get_by_text("Class token", exact=True).count() == 0
        page.screenshot(path=str(tmp_path / "lab.png"))

        # Another site's page (served from another port of this machine: another origin)
        # opens a websocket to the lab: the browser sends that page's Origin, and the lab
        # closes the connection.
        script = FOREIGN_PAGE.replace("WS_URL", f"ws://127.0.0.1:{port}").replace("PROTOCOL", PROTOCOL).replace(
            "CAMERA_BYTES", json.dumps(list(msgspec.msgpack.encode(CAMERA))))
        with _page_server(script) as other:
            foreign = page_factory()
            foreign.goto(f"{other}/")
            foreign.wait_for_function("window.seen.closed !== null", timeout=30000)
            seen = foreign.evaluate("window.seen")
        assert seen["closed"] == 1008, seen                 # policy violation, before any lab is built
        assert f"refused a tab from origin '{other}'" in log.read_text()
        assert not page.errors, page.errors
        print(f"\ntoken gate: field only before the token, lab after it; foreign origin: websocket {seen}")
