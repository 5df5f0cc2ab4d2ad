"""The Pole map tab in the browser (issue 11, defects 3, 9 and 15): the lab-wide colour legend,
the numbered pole table, each map's x range holding every pole (maglev_tracking's unstable
+36.4 rad/s included), the root locus in kalman_noise, ekf_parameters' closed loop and filter
error; and the locus follows a slider move.  Screenshots go to the test's tmp directory."""

from __future__ import annotations

import time

import pytest

from app.panels import pole_map
from lab_modules.evaluation import poles as pole_sets
from lab_modules.exercises import get
from tests.conftest import browser_only
from tests.page_reading import pole_maps as _maps
from tests.test_pole_map import first_analysis

pytestmark = browser_only


def test_pole_map_legend_ranges_and_locus(open_tab, tmp_path):
    tab = open_tab()
    page = tab.page
    page.get_by_role("heading", name=get("kalman_noise").title).wait_for(timeout=60000)
    tab.open_panel_tab("Pole map")
    page.get_by_text("Colours (every exercise)", exact=False).first.wait_for(timeout=20000)
    for category in pole_sets.CATEGORIES:
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
        assert m["strokes"][0] == pole_sets.BY_NAME["plant"].color, m
    page.screenshot(path=str(tmp_path / "maglev_tracking.png"))

    tab.switch_exercise(get("ekf_parameters").title)
    tab.open_panel_tab("Pole map")
    page.get_by_text("Colours (every exercise)", exact=False).first.wait_for(timeout=20000)
    labels = _maps(page)[1]["labels"]
    assert "closed loop (linear, rated k_i, k_x)" in labels and "filter error (x, v, i at rated k_i, k_x)" in labels
    page.screenshot(path=str(tmp_path / "ekf_parameters.png"))
    assert not tab.errors, tab.errors


def test_show_mode_rings_the_mode_and_names_it(open_tab, tmp_path):
    """Defect 15 ("no point says which mode it is"): choosing a mode in "Show mode" draws a ring
    series named after it on both maps, at the mode's pole, and shows its name, f_n, ζ and state
    participation; screenshots of the tab in three exercises go to the tmp directory."""
    tab = open_tab()
    page = tab.page
    exercise = get("kalman_noise")
    page.get_by_role("heading", name=exercise.title).wait_for(timeout=60000)
    tab.open_panel_tab("Pole map")
    values = exercise.resolve()
    view = pole_sets.view(exercise, values, first_analysis(exercise, values).poles)
    mode = next(m for m in pole_sets.modes(view.poles, view.names, view.shares)
                if m.label == "rotor position/velocity (suspension mode)")
    page.get_by_label("Show mode", exact=True).first.click()
    page.get_by_role("option", name=pole_map.mode_choice(mode), exact=True).click()
    ring = f"mode #{mode.number}: {mode.label}"
    deadline = time.time() + 60
    while time.time() < deadline and not all(ring in m["labels"] for m in _maps(page)):
        time.sleep(0.25)
    assert all(ring in m["labels"] for m in _maps(page)), _maps(page)
    maps = page.evaluate(RING_JS, ring)
    assert len(maps) == 2, maps
    for points in maps:                               # the ring sits on the pole and its mirror
        assert sorted(p[1] for p in points) == pytest.approx([-mode.pole.imag, mode.pole.imag], rel=1e-6)
        assert all(p[0] == pytest.approx(mode.pole.real, rel=1e-6) for p in points)
    detail = page.get_by_text(f"Mode #{mode.number}: {mode.label}", exact=False).first
    detail.wait_for(timeout=10000)
    assert page.get_by_text("State participation", exact=False).count()
    assert page.locator("table:visible").filter(has_text="share").count()
    page.set_viewport_size({"width": 1366, "height": 768})
    page.get_by_label("Show mode", exact=True).first.scroll_into_view_if_needed()
    page.screenshot(path=str(tmp_path / "kalman_noise_show_mode.png"))
    for name, wanted in (("lqg_vs_pid", "coil current estimate error"), ("sensor_placement", "PID integrator")):
        tab.switch_exercise(get(name).title)
        tab.open_panel_tab("Pole map")
        table = page.locator("table:visible").filter(has_text="f_n [Hz]").first
        table.wait_for(timeout=20000)
        deadline = time.time() + 20
        while time.time() < deadline and wanted not in table.inner_text():
            time.sleep(0.25)
        assert wanted in table.inner_text(), (name, wanted)
        page.screenshot(path=str(tmp_path / f"{name}_pole_map.png"), full_page=True)


#: the points [Re, Im] of the series labelled arguments[0] on every visible pole map
RING_JS = """(label) => Object.values((window.__viserTestpoints || {}).uplots || {}).map(v => v.chart)
    .filter(c => c.root.offsetParent !== null && /poles/i.test((c.root.querySelector('.u-title') || {}).innerText || ''))
    .map(c => { const k = c.series.findIndex(s => s.label === label);
                return k < 0 ? [] : Array.from(c.data[0], (x, r) => [x, c.data[k][r]]).filter(p => p[1] !== null && !isNaN(p[1])); })"""
