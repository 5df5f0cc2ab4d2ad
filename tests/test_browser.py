"""The lab in a real browser: Playwright drives Debian's Chromium."""

from __future__ import annotations

import os
import socket
import statistics
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
DEFAULT_NOISE = "1.3323"

pytestmark = [pytest.mark.browser,
              pytest.mark.skipif(not os.path.exists(CHROMIUM), reason="Debian's chromium is not installed")]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def lab_url():
    port = _free_port()
    server = subprocess.Popen([sys.executable, "-m", "app", "--port", str(port)], cwd=ROOT,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
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
    return page.locator("table").filter(has_text="RMS displacement").first.inner_text()


def _set_noise(page, index: int, value: str) -> float:
    """Type a sensor noise into the lab; return seconds until the readouts change."""
    before = _readouts(page)
    box = page.locator("input").nth(index)
    start = time.perf_counter()
    box.fill(value)
    box.press("Enter")
    deadline = start + 10
    while time.perf_counter() < deadline:
        if _readouts(page) != before:
            return time.perf_counter() - start
        time.sleep(0.005)
    raise AssertionError(f"readouts did not change after setting the noise to {value}")


def _visible_values(page) -> list:
    return page.locator("input").evaluate_all(
        "els => els.map(e => (e.offsetParent !== null && e.type !== 'hidden') ? e.value : null)")


def _noise_index(page) -> int:
    """The sensor-noise box: the first visible input showing the default noise."""
    values = _visible_values(page)
    if DEFAULT_NOISE not in values:
        raise AssertionError(f"no input shows the default noise {DEFAULT_NOISE}: {values}")
    return values.index(DEFAULT_NOISE)


def test_lab_in_two_tabs(lab_url):
    errors: list[str] = []
    with playwright.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=FLAGS)
        first = browser.new_page(viewport={"width": 1366, "height": 768})
        first.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        first.on("pageerror", lambda e: errors.append(str(e)))
        first.goto(lab_url)
        first.get_by_text("RMS displacement, measured feedback").first.wait_for(timeout=60000)
        initial = _readouts(first)
        noise_box = _noise_index(first)
        latencies = [_set_noise(first, noise_box, v) for v in ("2", "3", "4", "5", "2.5", "3.5")]
        assert _readouts(first) != initial

        second = browser.new_page(viewport={"width": 1366, "height": 768})
        second.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
        second.goto(lab_url)
        second.get_by_text("RMS displacement, measured feedback").first.wait_for(timeout=60000)
        time.sleep(1.0)
        values = _visible_values(second)
        assert DEFAULT_NOISE in values, "a new tab must start from the defaults, not another tab's settings"
        assert _readouts(second) != _readouts(first)
        browser.close()
    print(f"readout latency after a noise change: median {statistics.median(latencies) * 1e3:.0f} ms")
    assert not errors, errors
