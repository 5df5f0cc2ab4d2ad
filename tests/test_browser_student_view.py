"""Issue 25 in a browser: feedback where the student acts, charts that agree with the readouts,
every screen from 1024 x 768 to 1920 x 1080 (headless checks: tests/test_student_view.py)."""

from __future__ import annotations

import re
import time

import pytest

from lab_modules.exercises import get, registry
from lab_modules.exercises.ekf_parameters import CONVERGENCE_LABEL
from lab_modules.exercises.lqg_vs_pid import NO_OVERSHOOT
from lab_modules.exercises.maglev_tuning import SHIPPED_RECORDING
from tests.conftest import browser_only

pytestmark = browser_only

#: the visible uPlot charts: title, x and y scale ranges
CHARTS_JS = """() => Object.values((window.__viserTestpoints || {}).uplots || {}).map(v => v.chart)
    .filter(c => c.root.offsetParent !== null)
    .map(c => ({title: (c.root.querySelector('.u-title') || {}).innerText || '',
                x: [c.scales.x.min, c.scales.x.max], y: [c.scales.y.min, c.scales.y.max],
                xlabel: c.axes[0].label || ''}))"""
#: the visible elements holding ``text`` (innermost): their boxes [top, bottom] in the viewport
BOXES_JS = """text => [...document.querySelectorAll('p, td, div, span')].filter(e => e.offsetParent !== null
        && e.innerText.includes(text) && ![...e.children].some(c => c.innerText.includes(text)))
    .map(e => { const r = e.getBoundingClientRect(); return [r.top, r.bottom]; })"""


def _in_view(page, text: str) -> bool:
    """Whether ``text`` is on screen somewhere (not only below the fold of its panel or the window)."""
    height = page.viewport_size["height"]
    return any(top >= 0 and bottom <= height for top, bottom in page.evaluate(BOXES_JS, text))


def _slow_tab(open_tab):
    """A lab tab whose page waits up to 2 minutes for an element (the shared test machine is slow)."""
    tab = open_tab()
    tab.page.set_default_timeout(120_000)
    return tab


def _wait(predicate, timeout_s: float, what: str):
    deadline = time.time() + timeout_s
    while time.time() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(0.25)
    raise AssertionError(f"timed out: {what}")


def _open_folder(page, title: str) -> None:
    """Open the controls' folder ``title`` (its header is a clickable paper with the title as text)."""
    page.locator('div.mantine-Paper-root[style*="cursor: pointer"]', has_text=re.compile(f"^{re.escape(title)}$")) \
        .first.click()


def _choose(page, label: str, option: str) -> None:
    page.get_by_label(label, exact=True).first.click()
    page.get_by_role("option", name=option, exact=True).click()


def test_every_screen_keeps_controls_and_tabs_clear(open_tab):
    """1024 x 768: no notice over the charts' tabs, the 3D view folded away with a note, every panel
    tab usable; 1366 x 768: the 3D view back, the key readouts and the first chart in view; the
    browser tab names the lab and the exercise."""
    tab = _slow_tab(open_tab)
    page = tab.page
    page.set_viewport_size({"width": 1024, "height": 768})
    page.get_by_text("RMS displacement, measured feedback").first.wait_for(timeout=60000)
    page.get_by_text("Hidden: this window leaves the 3D view").wait_for(timeout=60000)
    assert page.title() == "AMB estimation lab — Kalman filter against sensor noise"
    notices = page.locator(".mantine-Notification-root")
    assert all(not notices.nth(i).is_visible() for i in range(notices.count()))
    for name in ("Pole map", "Analysis", "Worksheet", "Scope"):     # clicks reach every tab
        tab.open_panel_tab(name)
        assert page.get_by_role("tab", name=name).get_attribute("aria-selected") == "true"
    page.set_viewport_size({"width": 1366, "height": 768})
    _wait(lambda: not page.get_by_text("Hidden: this window leaves the 3D view").is_visible(), 20, "3D view back")
    for label in get("kalman_noise").key_readouts:
        assert _in_view(page, label), label
    first_chart = page.locator(".uplot:visible").first.bounding_box()
    assert first_chart["y"] < 768 - 100                           # the first scope chart starts in view
    assert not tab.errors, tab.errors


def test_key_readouts_are_in_view_above_live_plots_and_in_the_rotor_at_speed(open_tab):
    """At 1366 x 768 the key readouts sit above the live plots (self_sensing's ripple zoom pushed
    them below the fold) and rotor_at_speed's are in view; its long list is folded into groups."""
    tab = _slow_tab(open_tab)
    page = tab.page
    page.get_by_role("heading").first.wait_for(timeout=60000)
    for name in ("self_sensing", "rotor_at_speed"):
        exercise = get(name)
        tab.switch_exercise(exercise.title, timeout_ms=90000)
        page.get_by_text(exercise.key_readouts[0]).first.wait_for(timeout=90000)
        for label in exercise.key_readouts:
            _wait(lambda label=label: _in_view(page, label), 60, f"{name}: {label} in view")
    for group in ("Closed loop at this speed", "Unbalance"):
        summary = page.locator("summary", has_text=group).first
        assert summary.is_visible() and summary.evaluate("s => !s.parentElement.open"), group


def test_the_exercise_chooser_shows_every_title_whole_on_a_small_screen(open_tab):
    """1024 x 768: the chooser's list names every exercise by its whole title on one line (none cut
    off, none wrapped into a second line that reads as another entry)."""
    tab = _slow_tab(open_tab)
    page = tab.page
    page.set_viewport_size({"width": 1024, "height": 768})
    page.get_by_role("heading").first.wait_for(timeout=60000)
    page.get_by_label("Exercise", exact=True).first.click()
    options = page.get_by_role("option")
    options.first.wait_for()
    shown = options.evaluate_all("""os => os.map(o => ({text: o.innerText.trim(),
        whole: o.scrollWidth <= o.clientWidth + 1, right: o.getBoundingClientRect().right,
        height: o.getBoundingClientRect().height}))""")
    assert sorted(option["text"] for option in shown) == sorted(exercise.title for exercise in registry().values())
    assert all(option["whole"] and option["right"] <= 1024 for option in shown), shown
    heights = [option["height"] for option in shown]
    assert max(heights) < 1.5 * min(heights), shown                # one line each
    page.keyboard.press("Escape")


def test_upload_says_what_happened_under_the_button(open_tab, tmp_path):
    """A refused CSV (semicolons) and a loaded one: the line under "Load recording" says so, in view."""
    tab = _slow_tab(open_tab)
    page = tab.page
    page.get_by_role("heading").first.wait_for(timeout=60000)
    tab.switch_exercise(get("maglev_tuning").title, timeout_ms=90000)
    european = tmp_path / "european.csv"
    european.write_text("time_s;reference_mm;measured_position_mm;coil_voltage_v\n0,000;14,8;14,80213;22,354\n")
    page.locator("input[type=file]").first.set_input_files(str(european))
    page.get_by_text("separated by semicolons").wait_for(timeout=30000)
    assert _in_view(page, "separated by semicolons")
    button = page.get_by_text("Load recording (CSV)").bounding_box()
    (note_top, _), = page.evaluate(BOXES_JS, "separated by semicolons")
    assert 0 < note_top - (button["y"] + button["height"]) < 60       # right under the button
    page.locator("input[type=file]").first.set_input_files(str(SHIPPED_RECORDING))
    page.get_by_text("Loaded maglev_leadlag.csv").wait_for(timeout=30000)
    assert _in_view(page, "Loaded maglev_leadlag.csv") and not page.get_by_text("separated by semicolons").count()
    assert not tab.errors, tab.errors


def test_a_q_change_restarts_the_stopped_replay(open_tab):
    """maglev_tuning replayed to its end, then the Q preset changed: the replay runs again (the
    scope no longer keeps the old, stopped run)."""
    tab = _slow_tab(open_tab)
    page = tab.page
    page.get_by_role("heading").first.wait_for(timeout=60000)
    tab.switch_exercise(get("maglev_tuning").title, timeout_ms=90000)
    tab.set_number("Time scale [×]", "10")                        # 6 s of recording in 0.6 s
    page.get_by_text("Stopped: End of the recording").wait_for(timeout=60000)
    tab.set_number("Time scale [×]", "0.1")                       # slow: the next replay stays running
    time.sleep(2.0)
    assert page.get_by_text("Stopped: End of the recording").count()   # a time scale changes no result
    _open_folder(page, "Kalman filter")
    _choose(page, "Q preset", "table_3.1")
    page.get_by_text("Running", exact=True).wait_for(timeout=30000)
    _choose(page, "Time axis", "time since reset")
    innovation = _wait(lambda: next((c for c in page.evaluate(CHARTS_JS) if c["title"].startswith("Innovation")
                                     and c["xlabel"].startswith("time since reset")), None), 20, "since-reset scope")
    assert innovation["x"][0] < 2.0                               # early in the new run, not the old one's 6 s end
    assert not tab.errors, tab.errors


def test_ekf_parameters_reads_its_convergence_time_on_a_since_reset_scope(open_tab):
    """The convergence readout appears pinned above the charts, the k_i chart ranges over the
    estimate (not the starting ±3σ band of ±90 %) and pages its time since reset."""
    tab = _slow_tab(open_tab)
    page = tab.page
    page.get_by_role("heading").first.wait_for(timeout=60000)
    tab.switch_exercise(get("ekf_parameters").title, timeout_ms=90000)
    _choose(page, "Time axis", "time since reset")
    page.get_by_role("button", name="Reset").click()
    page.get_by_text(CONVERGENCE_LABEL).first.wait_for(timeout=90000)
    assert _in_view(page, CONVERGENCE_LABEL)
    ki = _wait(lambda: next((c for c in page.evaluate(CHARTS_JS) if c["title"].startswith("Force-current")
                             and c["xlabel"].startswith("time since reset")), None), 20, "k_i chart")
    assert ki["x"][1] - ki["x"][0] == pytest.approx(1.0)          # one 1 s page (time scale 0.2)
    time.sleep(4.0)                                               # past the start: the range may shrink
    ki = next(c for c in page.evaluate(CHARTS_JS) if c["title"].startswith("Force-current"))
    assert ki["y"][0] > 0 and ki["y"][1] - ki["y"][0] <= 100      # not −500 … 500 N/A
    assert not tab.errors, tab.errors


def test_lqg_vs_pid_i_pd_and_back_without_console_errors(open_tab):
    """The sequence that logged "Invalid array length": PID structure I-PD, the Analysis tab, back
    to PID, K = 0.325, twice; the I-PD overshoot reads as a word without a unit."""
    tab = _slow_tab(open_tab)
    page = tab.page
    page.get_by_role("heading").first.wait_for(timeout=60000)
    tab.switch_exercise(get("lqg_vs_pid").title, timeout_ms=120000)
    _open_folder(page, "PID")
    row = page.locator("tr").filter(has_text="PID: overshoot, reference step").first   # pinned above the scope
    for _ in range(2):
        _choose(page, "PID structure", "I-PD")
        _wait(lambda: NO_OVERSHOOT in row.inner_text(), 60, "the I-PD overshoot")
        assert row.locator("td").nth(2).inner_text().strip() == ""      # a word carries no unit
        tab.open_panel_tab("Analysis")
        time.sleep(3.0)
        _choose(page, "PID structure", "PID")
        tab.set_number("PID gain K [V/V]", "0.325")
        time.sleep(4.0)
        tab.set_number("PID gain K [V/V]", "0.65")
        tab.open_panel_tab("Scope")
        time.sleep(2.0)
    assert not tab.errors, tab.errors


def test_save_and_open_confirm_beside_their_buttons(open_tab):
    """Save names the code under the buttons; Open of that code (it switches the exercise) says so
    in view, in the folder beside the chooser."""
    tab = _slow_tab(open_tab)
    page = tab.page
    page.get_by_text("RMS displacement, measured feedback").first.wait_for(timeout=60000)
    _open_folder(page, "Saved experiment")
    page.get_by_role("button", name="Save").click()
    saved = page.get_by_text(re.compile(r"Saved as [A-Z]{2}(-[A-Z0-9]{4}){3}"))   # KN-7Q3M-X9TA-HPRW
    saved.wait_for(timeout=30000)
    code = re.search(r"[A-Z]{2}(-[A-Z0-9]{4}){3}", saved.inner_text()).group()
    tab.switch_exercise(get("thrust_liftoff").title, timeout_ms=90000)
    _open_folder(page, "Saved experiment")
    page.get_by_text("Experiment code", exact=True).locator("xpath=ancestor::div[.//input][1]//input").first.fill(code)
    page.get_by_role("button", name="Open").click()
    page.get_by_role("heading", name=get("kalman_noise").title, exact=True).wait_for(timeout=90000)
    page.get_by_text(f"Opened {code}").wait_for(timeout=30000)
    assert _in_view(page, f"Opened {code}")
    assert not tab.errors, tab.errors
