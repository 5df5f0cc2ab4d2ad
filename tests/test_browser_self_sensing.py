"""self_sensing in the browser: the live ripple zoom draws its traces and follows the
running simulation, the simulation-speed readout shows, and the Monte-Carlo button
brings its result (MC std / predicted σ̂ within [0.95, 1.05]) while the tab stays live."""

from __future__ import annotations

import re
import time

from lab_modules.exercises import get
from tests.conftest import browser_only

pytestmark = browser_only

#: the live ripple chart: its series count and finite points per series, and a fingerprint of its data
RIPPLE_JS = """() => { const c = Object.values((window.__viserTestpoints || {}).uplots || {}).map(v => v.chart)
    .find(c => ((c.root.querySelector('.u-title') || {}).innerText || '').startsWith('Ripple zoom'));
    if (!c) return null;
    return {series: c.data.length - 1, finite: c.data.slice(1).map(d => Array.from(d).filter(Number.isFinite).length),
            sum: Array.from(c.data[4]).reduce((a, b) => a + b, 0), y: [c.scales.y.min, c.scales.y.max]}; }"""

#: the largest time shown by the scope chart titled ``title`` (ms; the newest sample is at 0)
SCOPE_X_MAX_JS = """title => { const c = Object.values((window.__viserTestpoints || {}).uplots || {}).map(v => v.chart)
    .find(c => ((c.root.querySelector('.u-title') || {}).innerText || '') === title);
    return c ? Math.max(...Array.from(c.data[0]).filter(Number.isFinite)) : null; }"""


def test_ripple_zoom_speed_readout_and_monte_carlo_button(open_tab, lab_server):
    _, server_log = lab_server
    tab = open_tab()
    page = tab.page
    page.get_by_role("heading", name=get("kalman_noise").title).wait_for(timeout=60000)
    tab.switch_exercise(get("self_sensing").title)
    tab.open_panel_tab("Scope")
    page.get_by_text("Ripple zoom, live", exact=False).first.wait_for(timeout=20000)
    deadline = time.time() + 15
    ripple = page.evaluate(RIPPLE_JS)
    while (ripple is None or min(ripple["finite"]) == 0) and time.time() < deadline:
        time.sleep(0.25)
        ripple = page.evaluate(RIPPLE_JS)
    # shade band (2), measured and true current, four fitted lines, the hidden layout series (scope.LAYOUT_SERIES)
    assert ripple["series"] == 9 and ripple["finite"][2] == ripple["finite"][3] == 256, ripple
    assert all(0 < n <= 17 for n in ripple["finite"][4:8]), ripple
    assert ripple["y"][0] < ripple["y"][1]
    sums = {ripple["sum"]}
    for _ in range(8):                                # it follows the run (noise changes every period)
        time.sleep(0.3)
        sums.add(page.evaluate(RIPPLE_JS)["sum"])
    assert len(sums) > 1, "the ripple zoom stands still"
    speed = page.get_by_text("Simulation:", exact=False).first
    speed.wait_for(timeout=5000)
    assert re.search(r"0\.2\d*× real time", speed.inner_text()), speed.inner_text()

    page.get_by_role("button", name="Run Monte-Carlo").click()
    page.get_by_text("4 of 4 seeds done", exact=False).first.wait_for(timeout=60000)
    row = page.locator("tr").filter(has_text="MC std of L̄ − L / predicted").first
    ratio = float(row.locator("td").nth(1).inner_text())
    assert 0.95 <= ratio <= 1.05, ratio
    page.get_by_text("Monte-Carlo at 4 mm: (L̄ − L)", exact=False).first.wait_for(timeout=5000)

    # A new PWM period changes the sample time: the run keeps its time scale and the scope its window.
    page.get_by_text("Sampling", exact=True).first.click()          # its folder starts closed
    tab.set_number("T_pwm (fixed) [µs]", "2048")
    time.sleep(3)
    assert re.search(r"0\.2\d*× real time", speed.inner_text()), speed.inner_text()
    chart = get("self_sensing").charts[0]
    x_max = page.evaluate(SCOPE_X_MAX_JS, f"{chart.title} [{chart.unit}]")
    assert x_max is not None and -50 <= x_max <= 0.5, x_max
    page.screenshot(path=str(server_log.parent / "self_sensing.png"))
    assert not tab.errors, tab.errors
    warnings = [line for line in server_log.read_text().splitlines() if "Traceback" in line or "Error" in line]
    assert not warnings, warnings
