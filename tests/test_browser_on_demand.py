"""Analyses on demand in a real browser (issue 23): each panel tab's beacon tells the server when
the tab is shown, so the Analysis tab's figures are computed when it is opened, not while it is
hidden, and its beacon buttons are never seen."""

from __future__ import annotations

import re
import time

from lab_modules.exercises import get
from tests.conftest import browser_only

pytestmark = browser_only
#: the text of the Analysis tab's readouts (its tables, folded groups included), shown or hidden (a visited
#: tab stays in the page); not the key readouts pinned above the scope, which show the Analysis tab's figures
#: once it has computed them
ANALYSIS_TABLE_JS = """() => [...document.querySelectorAll('.lab-readouts')].map(t => t.textContent)
    .filter(t => t.includes('Largest gain factor, measured')).join('')"""


def test_the_analysis_tab_is_computed_when_shown_and_not_while_hidden(open_tab):
    tab = open_tab()
    page = tab.page
    page.get_by_role("heading", name=get("kalman_noise").title).wait_for(timeout=60000)
    page.get_by_text("RMS displacement, measured feedback").first.wait_for(timeout=60000)
    assert page.get_by_role("button", name=re.compile("panel (shown|hidden)")).count() == 0, "a beacon shows"
    assert page.evaluate(ANALYSIS_TABLE_JS) == ""
    opened = time.perf_counter()
    tab.open_panel_tab("Analysis")
    page.locator("table:visible").filter(has_text="Largest gain factor, measured").first.wait_for(timeout=30000)
    print(f"Analysis tab computed {time.perf_counter() - opened:.2f} s after it was opened")
    deadline = time.time() + 30
    while "computing" in page.evaluate(ANALYSIS_TABLE_JS) and time.time() < deadline:
        time.sleep(0.2)
    shown = page.evaluate(ANALYSIS_TABLE_JS)
    assert "gain margin" in shown and "computing" not in shown

    tab.open_panel_tab("Scope")
    tab.set_number("PID gain K [V/V]", "0.8")
    page.get_by_text("RMS displacement, measured feedback").first.wait_for(timeout=30000)
    time.sleep(4.0)                                    # read 1 s after the last key, then analysed
    assert page.evaluate(ANALYSIS_TABLE_JS) == shown, "the hidden Analysis tab was computed"
    tab.open_panel_tab("Analysis")
    deadline = time.time() + 30
    while page.evaluate(ANALYSIS_TABLE_JS) in (shown, "") and time.time() < deadline:
        time.sleep(0.2)
    assert page.evaluate(ANALYSIS_TABLE_JS) != shown, "the Analysis tab did not follow the new gain"
    assert page.get_by_role("button", name=re.compile("panel (shown|hidden)")).count() == 0
    assert not tab.errors, tab.errors


def test_analysis_charts_that_become_other_plots_while_shown_draw_without_errors(open_tab):
    """rotor_at_speed's Analysis tab, watched while it is computed: its quick result's two plots,
    then the margins' three, then the full result's eight, so charts change from one plot to
    another in view (uPlot threw 'Invalid array length' when a shown chart took another plot's
    series and data)."""
    tab = open_tab()
    page = tab.page
    page.get_by_role("heading", name=get("kalman_noise").title).wait_for(timeout=60000)
    tab.switch_exercise(get("rotor_at_speed").title, 90000)
    page.get_by_text("Closed loop at this speed").first.wait_for(timeout=60000)
    tab.open_panel_tab("Analysis")
    titles = page.locator(".u-title:visible")
    titles.filter(has_text="Stability limit against speed").first.wait_for(timeout=120000)
    page.get_by_text("Sensitivity |S|").first.wait_for(timeout=60000)
    shown = titles.all_inner_texts()
    assert len(shown) == 8 and shown[3].startswith("Stability limit against speed"), shown
    assert not tab.errors, tab.errors
