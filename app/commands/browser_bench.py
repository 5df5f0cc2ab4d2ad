"""``python -m app bench --browser``: how fast a slider move shows in the readouts,
and how much of the server one open tab costs.

Starts the lab on a free port, opens it in headless Chromium (Debian's, driven
by Playwright) at 1366 x 768 and clicks the position-noise slider of
``kalman_noise`` at twenty places, once per 3D-view refresh setting.  The
latency of one move is measured inside the page, as a student would see it:
from the pointer event that moves the slider to the first animation frame
after the readout row changed (a ``MutationObserver``), so the time
Playwright itself needs to send clicks and poll the page is not counted.

Server load: with 1, 2 and 4 tabs open on the default exercise (3D view at
its default refresh), the server process's CPU time per wall time (from
``/proc``, Linux only) over ``LOAD_WINDOW_S``, divided by the number of tabs:
the share of one core a student costs (the browser runs on the same machine
here; on a classroom server it does not).
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import statistics
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.commands.lab_processes import wait_http
from app.panels.scene_view import SCENE_REFRESH

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = "/usr/bin/chromium"
CHROMIUM_FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--no-first-run"]
VIEWPORT = {"width": 1366, "height": 768}      # the students' laptops
READOUT_MARK = "RMS displacement, measured feedback"   # a kalman_noise readout that follows the noise slider
#: Where the slider's track is clicked (fractions of its width): twenty places, alternately low and high
SLIDER_POSITIONS = tuple(np.linspace(0.1, 0.5, 20).reshape(2, 10).T.ravel())
TARGET_MS = 100
LOAD_TABS = (1, 2, 4)
LOAD_WINDOW_S = 10.0

#: Installed in the page: ``window.readoutLatencies`` collects, per change of the readout row
#: ``mark`` (the scope-window rows below it change every second anyway), [ms to the DOM
#: change, ms to the next frame] since the last pointer or input event.
LATENCY_PROBE = """mark => {
  const probe = {since: null, samples: []};
  window.readoutLatencies = probe.samples;
  const start = e => { probe.since = e.timeStamp; };
  document.addEventListener('pointerdown', start, true);
  document.addEventListener('input', start, true);
  const row = () => [...document.querySelectorAll('tr')].find(r => r.innerText.includes(mark));
  let shown = row() ? row().innerText : '';
  new MutationObserver(() => {
    const t = row();
    if (!t || t.innerText === shown) return;
    shown = t.innerText;
    if (probe.since === null) return;
    const since = probe.since, changed = performance.now();
    probe.since = null;
    requestAnimationFrame(() => probe.samples.push([changed - since, performance.now() - since]));
  }).observe(document.body, {subtree: true, childList: true, characterData: true});
}"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass(frozen=True)
class LabServer:
    url: str
    pid: int


@contextlib.contextmanager
def lab_server(log_path: Path, timeout_s: float = 120.0) -> Iterator[LabServer]:
    """The lab served by a child process on a free port; yields its URL and process id."""
    port = free_port()
    with log_path.open("w") as log:
        server = subprocess.Popen([sys.executable, "-m", "app", "--port", str(port),
                                   "--data-dir", str(log_path.parent / "lab-data")], cwd=ROOT,
                                  stdout=log, stderr=subprocess.STDOUT, text=True)
        url = f"http://127.0.0.1:{port}"
        try:
            wait_http(url, server, timeout_s, log_path)
            yield LabServer(url, server.pid)
        finally:
            server.terminate()
            server.wait(timeout=10)


def install_probe(page) -> None:
    page.evaluate(LATENCY_PROBE, READOUT_MARK)


def probed_latencies_ms(page) -> list[list[float]]:
    return page.evaluate("window.readoutLatencies")


def wait_for_new_sample(page, count: int, timeout_s: float = 10.0) -> None:
    deadline = time.perf_counter() + timeout_s
    while len(probed_latencies_ms(page)) == count:
        if time.perf_counter() > deadline:
            raise RuntimeError("the readouts did not change after a slider move")
        time.sleep(0.01)


def slider_latencies_ms(page, pause_s: float = 1.2) -> list[float]:
    """Click the first visible slider (the position-noise one) at ``SLIDER_POSITIONS``; ms to the shown readouts.

    The pause between moves outlasts the 3D view's hold after an input
    (``SCENE_QUIET_AFTER_INPUT_S``), so moves also land while it renders."""
    install_probe(page)
    track = page.locator(".mantine-Slider-track:visible").first.bounding_box()   # closed folders hide theirs
    for fraction in SLIDER_POSITIONS:
        count = len(probed_latencies_ms(page))
        page.mouse.click(track["x"] + fraction * track["width"], track["y"] + track["height"] / 2)
        wait_for_new_sample(page, count)
        time.sleep(pause_s)
    return [shown for _, shown in probed_latencies_ms(page)]


def measure(browser, url: str, refresh: str) -> list[float]:
    page = browser.new_page(viewport=VIEWPORT)
    try:
        page.goto(url)
        page.get_by_text(READOUT_MARK).first.wait_for(timeout=60000)
        page.get_by_label("3D view", exact=True).first.click()
        page.get_by_role("option", name=refresh, exact=True).click()
        time.sleep(3.0)                               # charts and scene settle
        return slider_latencies_ms(page)
    finally:
        page.close()


def cpu_seconds(pid: int) -> float:
    """User + system CPU time [s] of a process so far (Linux ``/proc``)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def server_load(browser, server: LabServer) -> dict[str, float]:
    """Server cores per open tab, for ``LOAD_TABS`` tabs open at once."""
    pages, load = [], {}
    try:
        for tabs in LOAD_TABS:
            while len(pages) < tabs:
                pages.append(browser.new_page(viewport=VIEWPORT))
                pages[-1].goto(server.url)
                pages[-1].get_by_text(READOUT_MARK).first.wait_for(timeout=60000)
            time.sleep(3.0)                           # the new tabs' start-up is not steady state
            cpu, start = cpu_seconds(server.pid), time.perf_counter()
            time.sleep(LOAD_WINDOW_S)
            load[str(tabs)] = (cpu_seconds(server.pid) - cpu) / (time.perf_counter() - start) / tabs
    finally:
        for page in pages:
            page.close()
    return load


def run(log_path: Path) -> dict:
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        raise RuntimeError("the browser benchmark needs Playwright: pip install -e '.[test]'") from None
    if not Path(CHROMIUM).exists():
        raise RuntimeError(f"the browser benchmark needs Chromium at {CHROMIUM} (Debian package 'chromium')")
    results = {}
    with lab_server(log_path) as server, sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_FLAGS)
        for refresh in SCENE_REFRESH:
            samples = measure(browser, server.url, refresh)
            results[refresh] = {"median_ms": statistics.median(samples), "samples_ms": samples}
        load = server_load(browser, server)
        browser.close()
    return {"measure": "slider move to the first frame showing new readouts (kalman_noise), in-page",
            "by_3d_view_refresh": results, "target_median_ms": TARGET_MS,
            "server_cores_per_tab": load}


def main(as_json: bool, log_path: Path) -> int:
    try:
        result = run(log_path)
    except RuntimeError as error:
        print(f"error: {error}", file=sys.stderr)
        return 1
    if as_json:
        print(json.dumps(result, indent=2))
    else:
        print(result["measure"])
        for refresh, figures in result["by_3d_view_refresh"].items():
            samples = ", ".join(f"{t:.0f}" for t in figures["samples_ms"])
            print(f"  3D view {refresh}: median {figures['median_ms']:.0f} ms ({samples})")
        print(f"  target: median < {TARGET_MS} ms")
        print("server load, share of one core per open tab:")
        for tabs, share in result["server_cores_per_tab"].items():
            print(f"  {tabs} tab(s) open: {share:.3f} per tab (about {1 / share:.0f} tabs per core)")
    return 0
