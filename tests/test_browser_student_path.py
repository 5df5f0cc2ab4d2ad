"""Issue 11 in the browser (one tab, three exercises): no "range" entry in the scope legends,
the lead-lag recording button answers next to itself (defect 5), and maglev_tuning's
still-segment sliders span the loaded 6 s recording, not 0-3600 s (defect 11)."""

from __future__ import annotations

from app.commands.browser_bench import VIEWPORT
from lab_modules.exercises import get
from tests.conftest import browser_only

pytestmark = browser_only


def test_legends_recording_note_and_still_segment_range(open_tab):
    tab = open_tab()
    page = tab.page
    page.get_by_role("heading", name=get("kalman_noise").title).wait_for(timeout=60000)
    page.locator(".u-legend:visible").first.wait_for(timeout=20000)   # closed folders hold hidden charts
    legends = page.locator(".u-legend:visible").all_inner_texts()
    assert legends and not any("range" in text for text in legends), legends

    tab.switch_exercise(get("maglev_tracking").title)
    page.get_by_role("button", name="Record a lead-lag run (CSV)").click()
    note = page.get_by_text("no recording: with sensor", exact=False).first
    note.wait_for(timeout=60000)
    box = note.bounding_box()
    assert box is not None and box["y"] + box["height"] <= VIEWPORT["height"], box   # above the fold

    tab.switch_exercise(get("maglev_tuning").title)
    for label in ("Still segment start [s]", "Still segment end [s]"):
        row = page.get_by_text(label, exact=True).locator("xpath=../../..")
        slider = row.get_by_role("slider").first
        slider.wait_for(timeout=10000)
        assert 5.0 < float(slider.get_attribute("aria-valuemax")) < 7.0, label
    assert not tab.errors, tab.errors
