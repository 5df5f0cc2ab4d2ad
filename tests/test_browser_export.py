"""Export and filter inspector in a real browser: the export buttons deliver files
(the scope window's CSV one window long, a chart's PNG), and while paused the
inspector steps one sample and shows the filter at it."""

from __future__ import annotations

import re
import time

from app.tab.state import window_rows
from lab_modules.exercises import get
from tests.conftest import browser_only

pytestmark = browser_only


def _window_rows(name: str) -> int:
    exercise = get(name)
    values = exercise.resolve({})
    return window_rows(values, exercise.simulation(values).sample_time_s)


def test_export_downloads_and_inspector_steps(open_tab, tmp_path):
    tab = open_tab()
    page = tab.page
    page.get_by_role("heading", name=get("kalman_noise").title).wait_for(timeout=60000)
    time.sleep(6.0)                                            # about a scope window (5 s at time scale 0.01)
    page.get_by_role("button", name="Pause").click()

    page.get_by_text("Filter inspector", exact=True).click()  # open the folder
    page.get_by_role("button", name="Step one sample").click()
    page.get_by_text("Linear Kalman filter (paper 000, eq. 2)").wait_for(timeout=10000)
    first = int(re.search(r"\(sample (\d+)\)", page.get_by_text("(sample").first.inner_text()).group(1))
    page.get_by_role("button", name="Step one sample").click()
    page.get_by_text(f"(sample {first + 1})").wait_for(timeout=10000)
    for text in ("±σ = √P_ii", "Correlations", "predicted σ = √S", "position sensor"):
        assert page.get_by_text(text).first.is_visible(), text

    page.get_by_text("Export for your report", exact=True).click()
    with page.expect_download(timeout=30000) as download:
        page.get_by_role("button", name="Scope window (CSV)").click()
    name = download.value.suggested_filename
    assert re.fullmatch(r"kalman_noise_KN-[A-Z0-9]{4}-[A-Z0-9]{4}-[A-Z0-9]{4}_\d{8}-\d{6}_scope\.csv", name), name
    path = tmp_path / name
    download.value.save_as(path)
    lines = [line for line in path.read_text().splitlines() if not line.startswith("#")]
    assert lines[0].startswith("time_s [s],x_true_m [m],")
    times = [float(line.split(",", 1)[0]) for line in lines[1:]]
    T = get("kalman_noise").simulation(get("kalman_noise").resolve({})).sample_time_s
    assert round((times[-1] - times[0]) / T) + 1 == len(times)             # every sample, none skipped
    assert len(times) == _window_rows("kalman_noise") or times[0] == 0.0    # the window, or all of a short run

    with page.expect_download(timeout=30000) as picture:
        page.get_by_role("button", name="Chart: Rotor position (PNG)").click()
    assert picture.value.suggested_filename.endswith("_rotor-position.png")
    png = tmp_path / picture.value.suggested_filename
    picture.value.save_as(png)
    assert png.read_bytes()[:4] == b"\x89PNG"
    assert not tab.errors, tab.errors
