"""The sensor_placement exercise in a real browser (Playwright + Debian's Chromium):
moving the sensor from the external track into the bearing plane changes the
readouts, without console errors; the frame rate of the page with its 3D view is
printed."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

playwright = pytest.importorskip("playwright.sync_api")
CHROMIUM = "/usr/bin/chromium"
FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
         "--disable-component-update", "--disable-sync", "--no-first-run"]
ROOT = Path(__file__).resolve().parent.parent
DEFAULT_OFFSET = "60"

pytestmark = [pytest.mark.browser,
              pytest.mark.skipif(not os.path.exists(CHROMIUM), reason="Debian's chromium is not installed")]

FRAME_RATE_JS = """() => new Promise(done => {
    let frames = 0; const start = performance.now();
    function tick() { frames++; if (performance.now() - start < 3000) requestAnimationFrame(tick);
                      else done(frames * 1000 / (performance.now() - start)); }
    requestAnimationFrame(tick); })"""


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def lab_url():
    port = _free_port()
    server = subprocess.Popen([sys.executable, "-m", "app", "--port", str(port), "--exercise", "sensor_placement"],
                              cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    deadline = time.time() + 120
    while time.time() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                break
        if server.poll() is not None:
            pytest.fail(f"server exited: {server.stdout.read()}")
        time.sleep(0.5)
    yield f"http://127.0.0.1:{port}"
    server.terminate()
    server.wait(timeout=10)


def _readouts(page) -> str:
    return page.locator("table").filter(has_text="Largest stable gain factor here").first.inner_text()


def _wait_for_change(page, before: str, timeout_s: float = 15.0) -> str:
    deadline = time.time() + timeout_s
    while time.time() < deadline:
        now = _readouts(page)
        if now != before:
            time.sleep(0.5)                       # let a second (fuller) analysis land
            return _readouts(page)
        time.sleep(0.02)
    raise AssertionError("the readouts did not change after moving the sensor")


def _row(table: str, label: str) -> str:
    return next(line for line in table.splitlines() if line.startswith(label))


def test_moving_the_sensor_into_the_bearing_plane(lab_url):
    errors: list[str] = []
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=FLAGS)
        page = browser.new_page(viewport={"width": 1366, "height": 768})
        page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(lab_url)
        page.get_by_text("Largest stable gain factor here").first.wait_for(timeout=60000)
        external = _readouts(page)
        assert "-1" in _row(external, "Mode 3: residue sign")
        assert "eddy-current" in external

        values = page.locator("input").evaluate_all(
            "els => els.map(e => (e.offsetParent !== null && e.type !== 'hidden') ? e.value : null)")
        box = page.locator("input").nth(values.index(DEFAULT_OFFSET))
        box.fill("0")
        box.press("Enter")
        collocated = _wait_for_change(page, external)
        assert "integrated capacitive" in collocated
        assert "-1" not in _row(collocated, "Mode 3: residue sign")
        assert _row(collocated, "Largest stable gain factor here") != _row(external, "Largest stable gain factor here")

        frame_rate = page.evaluate(FRAME_RATE_JS)
        browser.close()
    print(f"3D view: {frame_rate:.1f} frames/s in headless Chromium (software WebGL)")
    assert frame_rate > 1.0
    assert not errors, errors
