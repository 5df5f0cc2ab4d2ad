"""Every exercise in one browser tab: switched with the Exercise dropdown, each
shows numeric readouts, live scope charts and its Pole map, Analysis and
Worksheet tabs, without console or page errors, and the server logs no warnings."""

from __future__ import annotations

import re
import time

from lab_modules.exercises import get, registry
from tests.conftest import browser_only

pytestmark = browser_only


CLIPPED_JS = """() => [...document.querySelectorAll('table, .uplot, label, h1, h2, h3, p, input')]
    .filter(el => el.offsetParent !== null && el.getBoundingClientRect().width > 0)
    .filter(el => el.getBoundingClientRect().right > window.innerWidth + 1 || el.scrollWidth > el.clientWidth + 1)
    .map(el => el.tagName + ': ' + (el.innerText || el.value || '').slice(0, 60))"""


def _clipped(page) -> list[str]:
    """Visible tables, charts, labels, texts and number boxes cut off at the right."""
    return page.evaluate(CLIPPED_JS)


def _readout_table(page):
    return page.locator("table").filter(has_text="quantity").first


def _scope_runs(page) -> bool:
    """The first scope chart's pixels change, or the run stopped (an unstable default
    setting is a lesson: the status line then says why)."""
    chart = page.locator(".uplot").first
    before = chart.screenshot()
    deadline = time.time() + 15
    while time.time() < deadline:
        time.sleep(0.2)
        if page.get_by_text("Stopped:").count() or chart.screenshot() != before:
            return True
    return False


def test_every_exercise_in_one_tab(open_tab, lab_server):
    _, server_log = lab_server
    tab = open_tab()
    page = tab.page
    exercises = list(registry().values())
    page.get_by_role("heading", name=exercises[0].title).wait_for(timeout=60000)
    for exercise in exercises:
        if exercise is not exercises[0]:
            tab.switch_exercise(exercise.title)
        tab.open_panel_tab("Scope")
        table = _readout_table(page)
        table.wait_for(timeout=20000)
        assert any(re.search(r"\d", cell) for cell in table.locator("td").all_inner_texts()), exercise.name
        assert _scope_runs(page), f"{exercise.name}: the scope does not update"
        assert not _clipped(page), (exercise.name, _clipped(page))
        tab.open_panel_tab("Pole map")
        page.get_by_text("dominant poles", exact=False).first.wait_for(timeout=10000)
        page.locator("table").filter(has_text="Im s [rad/s]").first.wait_for(timeout=10000)
        assert not _clipped(page), (exercise.name, _clipped(page))
        if page.get_by_role("tab", name="Analysis").count():
            tab.open_panel_tab("Analysis")
            page.locator(".uplot:visible").first.wait_for(timeout=10000)
            assert not _clipped(page), (exercise.name, _clipped(page))
        tab.open_panel_tab("Worksheet")
        page.get_by_role("heading", name=re.compile("Worksheet|Sensor placement")).first.wait_for(timeout=10000)
    page.close()
    time.sleep(1.0)                                   # the server notices the closed tab
    assert not tab.errors, tab.errors
    warnings = [line for line in server_log.read_text().splitlines() if "closed connection" in line
                or "Traceback" in line or "Error" in line]
    assert not warnings, warnings


def test_a_stopped_simulation_says_why_and_recovers(open_tab):
    """Four times the PID gains lets kalman_noise's rotor touch down: the status line
    and a notification say so; Reset restarts it, and Run on sane gains keeps it running."""
    tab = open_tab()
    page = tab.page
    page.get_by_role("heading", name=get("kalman_noise").title).wait_for(timeout=60000)
    tab.set_number("Common gain factor [×]", "4")
    page.get_by_text("Stopped: Touchdown").wait_for(timeout=20000)
    page.get_by_text("Simulation stopped").wait_for(timeout=5000)
    page.get_by_role("button", name="Reset").click()
    page.get_by_text("Running", exact=True).wait_for(timeout=5000)
    page.get_by_text("Stopped: Touchdown").wait_for(timeout=20000)     # the same gains touch down again
    unstable = _readout_table(page).inner_text()
    tab.set_number("Common gain factor [×]", "1")
    deadline = time.time() + 10
    while _readout_table(page).inner_text() == unstable and time.time() < deadline:
        time.sleep(0.05)                              # until the change has landed
    page.get_by_role("button", name="Run").click()
    page.get_by_text("Running", exact=True).wait_for(timeout=5000)
    time.sleep(2.0)
    assert page.get_by_text("Stopped:").count() == 0
    assert not tab.errors, tab.errors


def test_record_a_run_in_the_browser_and_load_it_into_the_tuning_exercise(open_tab, tmp_path):
    """The maglev workflow of §3.5 in the browser: record a lead-lag run in the
    tracking exercise (a CSV download), switch to the tuning exercise, upload it."""
    tab = open_tab()
    page = tab.page
    page.get_by_role("heading", name=get("kalman_noise").title).wait_for(timeout=60000)
    tab.switch_exercise(get("maglev_tracking").title)
    page.get_by_role("button", name="Record a lead-lag run (CSV)").click()
    page.get_by_text("no recording: with sensor_noise_mm = 1").wait_for(timeout=20000)   # 1 mm loses the ball
    page.get_by_text("Plant", exact=True).click()                                         # open the folder
    tab.set_number("log₁₀ Sensor noise σ [mm]", "-2")                                    # 0.01 mm
    with page.expect_download(timeout=30000) as download:
        page.get_by_role("button", name="Record a lead-lag run (CSV)").click()
    path = tmp_path / download.value.suggested_filename
    download.value.save_as(path)
    assert "noise_0.01mm" in path.name
    tab.switch_exercise(get("maglev_tuning").title)
    with page.expect_file_chooser(timeout=10000) as chooser:
        page.get_by_role("button", name="Load recording (CSV)").click()
    chooser.value.set_files(path)
    page.get_by_text(f"Loaded {path.name}.").wait_for(timeout=20000)
    assert not tab.errors, tab.errors


def _visible_learning_goals(page) -> int:
    return page.get_by_role("heading", name="Learning goals").evaluate_all(
        "els => els.filter(e => e.offsetParent !== null && e.getBoundingClientRect().width > 0).length")


def test_worksheet_beside_the_charts(open_tab):
    """Self-paced work: the worksheet takes the 3D view's place while the Scope stays open,
    follows an exercise switch, and goes away again."""
    tab = open_tab()
    page = tab.page
    page.get_by_text("RMS displacement, measured feedback").first.wait_for(timeout=60000)
    tab.open_panel_tab("Scope")
    assert _visible_learning_goals(page) == 0
    page.get_by_text("Worksheet beside the charts").first.click()
    page.wait_for_function("() => [...document.querySelectorAll('h3, h2, h4')].some("
                           "e => e.innerText === 'Learning goals' && e.offsetParent !== null)", timeout=10000)
    assert page.locator(".uplot").first.is_visible(), "the scope must stay in view"
    tab.switch_exercise(get("lqg_vs_pid").title)
    page.get_by_text("Worksheet: the LQG regulator", exact=False).first.wait_for(state="visible", timeout=20000)
    page.get_by_text("Worksheet beside the charts").first.click()
    deadline = time.time() + 10
    while _visible_learning_goals(page) and time.time() < deadline:
        time.sleep(0.2)
    assert _visible_learning_goals(page) == 0
    assert not tab.errors, tab.errors
