"""The sensor_placement exercise in a real browser: moving the sensor from the
external track into the bearing plane changes the readouts, without console
errors; the frame rate of the page with its 3D view is printed."""

from __future__ import annotations

import time

from lab_modules.exercises import get
from tests.conftest import browser_only

pytestmark = browser_only
DEFAULT_OFFSET = "60"

FRAME_RATE_JS = """() => new Promise(done => {
    let frames = 0; const start = performance.now();
    function tick() { frames++; if (performance.now() - start < 3000) requestAnimationFrame(tick);
                      else done(frames * 1000 / (performance.now() - start)); }
    requestAnimationFrame(tick); })"""


def _readouts(page) -> str:
    return page.locator("table").filter(has_text="Largest stable gain factor here").filter(
        has_text="residue sign").first.inner_text()              # the whole table, not the pinned key readouts


def _wait_for(page, text: str, timeout_s: float = 15.0) -> str:
    """The readouts once they name ``text`` (the scope-window rows change every second anyway)."""
    deadline = time.time() + timeout_s
    while time.time() < deadline:
        if text in _readouts(page):
            time.sleep(0.5)                       # let a second (fuller) analysis land
            return _readouts(page)
        time.sleep(0.05)
    raise AssertionError(f"the readouts did not name {text!r} after moving the sensor")


def _row(table: str, label: str) -> str:
    return next(line for line in table.splitlines() if line.startswith(label))


def test_moving_the_sensor_into_the_bearing_plane(open_tab):
    tab = open_tab()
    page = tab.page
    page.get_by_role("heading").first.wait_for(timeout=60000)
    tab.switch_exercise(get("sensor_placement").title)
    page.get_by_text("Largest stable gain factor here").first.wait_for(timeout=60000)
    external = _readouts(page)
    assert "-1" in _row(external, "Mode 3: residue sign")
    assert "eddy-current" in external

    box = page.locator("input").nth(tab.visible_input_values().index(DEFAULT_OFFSET))
    box.fill("0")
    box.press("Enter")
    collocated = _wait_for(page, "integrated capacitive")
    assert "-1" not in _row(collocated, "Mode 3: residue sign")
    assert _row(collocated, "Largest stable gain factor here") != _row(external, "Largest stable gain factor here")

    frame_rate = page.evaluate(FRAME_RATE_JS)
    print(f"3D view: {frame_rate:.1f} frames/s in headless Chromium (software WebGL)")
    assert frame_rate > 1.0
    assert not tab.errors, tab.errors
