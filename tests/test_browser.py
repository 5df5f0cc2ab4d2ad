"""The lab in a real browser: two tabs with their own settings; the slider-to-readout
latency is printed (not asserted: speed belongs to ``python -m app bench --browser``)."""

from __future__ import annotations

import statistics
import time

from app.commands.browser_bench import slider_latencies_ms
from tests.conftest import browser_only

pytestmark = browser_only
DEFAULT_NOISE = "1.3323"


def _readouts(page) -> str:
    """The readout row that follows the noise (the scope-window rows change every second anyway)."""
    return page.locator("tr").filter(has_text="RMS displacement, measured feedback").first.inner_text()


def _set_noise(page, index: int, value: str) -> None:
    """Type a sensor noise into the lab and wait until the readouts change."""
    before = _readouts(page)
    box = page.locator("input").nth(index)
    box.fill(value)
    box.press("Enter")
    deadline = time.perf_counter() + 10
    while _readouts(page) == before:
        if time.perf_counter() > deadline:
            raise AssertionError(f"readouts did not change after setting the noise to {value}")
        time.sleep(0.02)


def _noise_index(tab) -> int:
    """The sensor-noise box: the first visible input showing the default noise."""
    values = tab.visible_input_values()
    if DEFAULT_NOISE not in values:
        raise AssertionError(f"no input shows the default noise {DEFAULT_NOISE}: {values}")
    return values.index(DEFAULT_NOISE)


def test_lab_in_two_tabs(open_tab):
    first = open_tab()
    first.page.get_by_text("RMS displacement, measured feedback").first.wait_for(timeout=60000)
    initial = _readouts(first.page)
    noise_box = _noise_index(first)
    _set_noise(first.page, noise_box, "3")
    assert _readouts(first.page) != initial
    latencies = slider_latencies_ms(first.page, pause_s=0.3)    # moves the noise slider; must change readouts

    second = open_tab()
    second.page.get_by_text("RMS displacement, measured feedback").first.wait_for(timeout=60000)
    time.sleep(1.0)
    assert DEFAULT_NOISE in second.visible_input_values(), \
        "a new tab must start from the defaults, not another tab's settings"
    assert _readouts(second.page) != _readouts(first.page)
    window_row = second.page.locator("tr").filter(has_text="RMS displacement, this run (scope window)").first
    window_row.wait_for(timeout=10000)
    before = window_row.inner_text()
    time.sleep(2.5)
    assert window_row.inner_text() != before, "the scope-window readouts must follow the running simulation"
    print(f"slider move to readouts shown: median {statistics.median(latencies):.0f} ms "
          f"(of {', '.join(f'{t:.0f}' for t in latencies)} ms)")
    assert not first.errors + second.errors, first.errors + second.errors
