"""thrust_liftoff in the browser: its scope, pole map, analysis and worksheet show
without console errors, and a Kp below |k_x|/k_i stops the run with the reason."""

from __future__ import annotations

import re

from lab_modules.exercises import get
from tests.conftest import browser_only

pytestmark = browser_only


def test_thrust_liftoff_views_and_unstable_kp(open_tab, lab_server):
    _, server_log = lab_server
    tab = open_tab()
    page = tab.page
    page.get_by_role("heading", name=get("kalman_noise").title).wait_for(timeout=60000)
    tab.switch_exercise(get("thrust_liftoff").title)
    tab.open_panel_tab("Scope")
    page.get_by_text("Bias current i0", exact=False).first.wait_for(timeout=20000)
    page.get_by_text("Noise-free overshoot, raw PID", exact=False).first.wait_for(timeout=20000)
    tab.open_panel_tab("Pole map")
    page.locator("table:visible").filter(has_text="f_n [Hz]").first.wait_for(timeout=10000)
    tab.open_panel_tab("Analysis")
    page.locator(".uplot:visible").first.wait_for(timeout=10000)
    tab.open_panel_tab("Worksheet")
    page.get_by_role("heading", name=re.compile("Worksheet: thrust bearing")).first.wait_for(timeout=10000)
    tab.open_panel_tab("Scope")
    page.get_by_text("Controller", exact=True).first.wait_for(timeout=5000)
    tab.set_number("Proportional gain Kp [A/mm]", "0.5")
    page.get_by_text("The loop is unstable", exact=False).first.wait_for(timeout=30000)
    page.get_by_text("Stopped:", exact=False).first.wait_for(timeout=30000)
    assert not tab.errors, tab.errors
    warnings = [line for line in server_log.read_text().splitlines() if "Traceback" in line or "Error" in line]
    assert not warnings, warnings
