"""The filter debugger in a real browser: paused, it steps back 10 samples and the typeset
equations' sample, the ellipse chart and the consistency readouts follow; the 3D view shows the
ellipsoids of three states in place of the rig, and the rig again when the simulation runs."""

from __future__ import annotations

import os
import re
import time

from lab_modules.exercises import get
from tests.conftest import browser_only

pytestmark = browser_only


def test_debugger_steps_back_ten_samples(open_tab):
    tab = open_tab()
    page = tab.page
    page.get_by_role("heading", name=get("kalman_noise").title).wait_for(timeout=60000)
    time.sleep(3.0)
    page.get_by_role("button", name="Pause").click()
    page.get_by_text("Filter debugger", exact=True).click()             # open the folder
    page.get_by_text("are kept: step back").wait_for(timeout=20000)
    title = page.get_by_text(re.compile(r"^Sample \d+, t = ")).first
    newest = int(re.search(r"Sample (\d+)", title.inner_text()).group(1))
    page.get_by_text(f"P⁻ and P⁺ at sample {newest}").wait_for(timeout=10000)
    before = page.get_by_text(f"P⁻ and P⁺ at sample {newest}").locator("xpath=..").screenshot()
    page.get_by_role("button", name="◀ 10").click()
    page.get_by_text(re.compile(rf"^Sample {newest - 10}, t = ")).wait_for(timeout=10000)
    page.get_by_text(f"P⁻ and P⁺ at sample {newest - 10}").wait_for(timeout=10000)
    after = page.get_by_text(f"P⁻ and P⁺ at sample {newest - 10}").locator("xpath=..").screenshot()
    assert before != after                                              # the ellipses moved
    t_newest, t_back = (newest * 50e-6 * 1e3, (newest - 10) * 50e-6 * 1e3)
    assert page.get_by_text(f"t = {t_back:.3f} ms").first.is_visible() and t_back < t_newest
    assert page.get_by_text("Consistency over the").first.is_visible()
    assert page.get_by_text("NEES (3 dof)").first.is_visible()
    if os.environ.get("LAB_SCREENSHOTS"):
        page.screenshot(path=os.path.join(os.environ["LAB_SCREENSHOTS"], "filter_debugger.png"), full_page=True)

    canvas = page.locator("canvas").first
    rig = _settled(canvas)
    page.get_by_label("Ellipsoids in 3D", exact=True).click()
    page.get_by_role("option", name="x / v / i", exact=True).click()
    ellipsoids = _settled(canvas)
    assert ellipsoids != rig
    page.get_by_role("button", name="1 ▶").click()                     # the next sample's update shrinks P
    page.get_by_text(re.compile(rf"^Sample {newest - 9}, t = ")).wait_for(timeout=10000)
    assert _settled(canvas) != ellipsoids
    if os.environ.get("LAB_SCREENSHOTS"):
        page.screenshot(path=os.path.join(os.environ["LAB_SCREENSHOTS"], "filter_debugger_3d.png"))
    page.get_by_role("button", name="Run").click()
    page.get_by_text("Pause the simulation to step back").wait_for(timeout=10000)
    assert _settled(canvas) != ellipsoids                               # the rig is back
    assert not tab.errors, tab.errors


def _settled(canvas) -> bytes:
    """The 3D view once it has drawn what it was sent."""
    time.sleep(1.5)
    return canvas.screenshot()
