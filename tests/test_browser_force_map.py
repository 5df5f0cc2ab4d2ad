"""The 3D maps of paper 002 in a real browser (1366×768, software WebGL): the
stiffness map's force surface and, switched with "3D view shows", the FBFNN k_i
surface whose legend follows the training; adaptive_filter's operating-point
marker whose legend follows the loop.  No console or page errors."""

from __future__ import annotations

import time

from app.tab.analysis_view import analyses as _analyses
from lab_modules.evaluation import margins
from lab_modules.exercises import get
from tests.conftest import browser_only

pytestmark = browser_only


VIEW_CLIP = {"x": 390, "y": 200, "width": 370, "height": 450}   # the 3D view between the docked panels


def _view(page):
    import io

    import numpy as np
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(page.screenshot(clip=VIEW_CLIP))).convert("RGB")).astype(int)


def _pixels(page, kind: str) -> int:
    """Strongly red or green pixels in the 3D view (the labels are drawn in WebGL, not the DOM)."""
    import numpy as np

    image = _view(page)
    r, g, b = image[..., 0], image[..., 1], image[..., 2]
    mask = {"red": (r - g > 60) & (r - b > 60), "green": (g - r > 60) & (g - b > 60)}[kind]
    return int(np.sum(mask))


def _view_changes(page, within_s: float = 20.0) -> bool:
    """The 3D view's pixels change (it follows the simulation at 1 update/s)."""
    import numpy as np

    first = _view(page)
    deadline = time.time() + within_s
    while time.time() < deadline:
        time.sleep(1.0)
        if np.mean(np.abs(_view(page) - first)) > 0.05:
            return True
    return False


def test_stiffness_surfaces_and_operating_point_marker(open_tab):
    tab = open_tab()
    page = tab.page
    page.get_by_text("Running").first.wait_for(timeout=60000)
    tab.switch_exercise(get("stiffness_map").title)
    time.sleep(4.0)
    red = _pixels(page, "red")
    assert red > 500, f"the force surface is not drawn ({red} red pixels)"
    force_view = _view(page)
    page.get_by_text("3D view", exact=True).last.click()
    page.get_by_label("3D view shows").first.click()
    page.get_by_role("option", name="k_i", exact=True).click()
    time.sleep(3.0)
    assert abs(_view(page) - force_view).mean() > 2.0, "the force surface is still shown"
    assert _view_changes(page), "the FBFNN surface does not follow the training"
    tab.switch_exercise(get("adaptive_filter").title)
    time.sleep(4.0)
    assert _pixels(page, "green") > 30, "no operating-point marker"
    assert _view_changes(page), "the operating-point marker does not move"
    assert not tab.errors, tab.errors


TITLES_JS = """() => [...document.querySelectorAll('.u-title')].filter(e => e.offsetParent !== null)
    .map(e => e.innerText)"""


def test_analysis_tab_shows_the_plots_of_the_full_analysis(open_tab):
    """stiffness_map yields a quick analysis (4 plots) and then the full one (10): the Analysis tab
    must show all ten, among them the MISO ADALINE's force and weights."""
    tab = open_tab()
    page = tab.page
    page.get_by_text("Running").first.wait_for(timeout=60000)
    tab.switch_exercise(get("stiffness_map").title)
    tab.open_panel_tab("Analysis")
    exercise = get("stiffness_map")
    values = exercise.resolve()
    *_, full = _analyses(exercise, values)            # the last result: every plot
    expected = len(margins.with_margins(full, margins.margin_view(exercise, values)).plots)
    deadline = time.time() + 60
    titles = page.evaluate(TITLES_JS)
    while len(titles) < expected and time.time() < deadline:
        time.sleep(1.0)
        titles = page.evaluate(TITLES_JS)
    assert len(titles) == expected, titles
    assert any(t.startswith("MISO ADALINE: magnet force") for t in titles), titles
    assert any(t.startswith("MISO ADALINE weights") for t in titles), titles
    assert not tab.errors, tab.errors
