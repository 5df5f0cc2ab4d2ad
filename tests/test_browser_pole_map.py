"""The Pole map tab in the browser (issue 11, defects 3, 9 and 15): the lab-wide colour legend,
the numbered pole table, each map's x range holding every pole (maglev_tracking's unstable
+36.4 rad/s included), the root locus in kalman_noise, ekf_parameters' closed loop and filter
error; and the locus follows a slider move.  Screenshots go to the test's tmp directory."""

from __future__ import annotations

import time

from app import pole_map
from lab_modules.exercises import get
from tests.conftest import browser_only
from tests.page_reading import pole_maps as _maps

pytestmark = browser_only


def test_pole_map_legend_ranges_and_locus(open_tab, tmp_path):
    tab = open_tab()
    page = tab.page
    page.get_by_role("heading", name=get("kalman_noise").title).wait_for(timeout=60000)
    tab.open_panel_tab("Pole map")
    page.get_by_text("Colours (every exercise)", exact=False).first.wait_for(timeout=20000)
    for category in pole_map.CATEGORIES:
        assert page.get_by_text(category.meaning, exact=False).count(), category
    table = page.locator("table:visible").filter(has_text="f_n [Hz]").first
    table.wait_for(timeout=10000)
    assert "rotor position (unstable magnet pole)" in table.inner_text()   # the physical name (mode_names)
    maps = _maps(page)
    assert all(any(label.startswith("root locus") for label in m["labels"]) for m in maps), maps
    page.screenshot(path=str(tmp_path / "kalman_noise.png"))

    tab.open_panel_tab("Scope")                      # a slider move redraws the locus
    tab.set_number("PID gain K [V/V]", "0.8")
    tab.open_panel_tab("Pole map")
    deadline = time.time() + 20
    while time.time() < deadline and maps == _maps(page):
        time.sleep(0.3)
    assert _maps(page) != maps, "the pole maps did not follow the slider"

    tab.switch_exercise(get("maglev_tracking").title)
    tab.open_panel_tab("Pole map")
    page.get_by_text("Colours (every exercise)", exact=False).first.wait_for(timeout=20000)
    for m in _maps(page):
        assert m["x"][1] > 36.4 * 1.05, m                 # defect 3: the unstable open-loop pole
        assert m["strokes"][0] == pole_map.BY_NAME["plant"].color, m
    page.screenshot(path=str(tmp_path / "maglev_tracking.png"))

    tab.switch_exercise(get("ekf_parameters").title)
    tab.open_panel_tab("Pole map")
    page.get_by_text("Colours (every exercise)", exact=False).first.wait_for(timeout=20000)
    labels = _maps(page)[1]["labels"]
    assert "closed loop (linear, rated k_i, k_x)" in labels and "filter error (x, v, i at rated k_i, k_x)" in labels
    page.screenshot(path=str(tmp_path / "ekf_parameters.png"))
    assert not tab.errors, tab.errors
