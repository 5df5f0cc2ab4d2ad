"""A tab whose Scope tab is hidden (the student reads the Pole map, the Analysis or the
Worksheet) gets no scope charts: nobody sees them, and half a class at work is on another panel.
Back on the Scope, the whole window comes at once, even if the run was paused meanwhile.  Raw websocket tab against
a lab process (loopback); the browser reports the Scope tab through its beacon buttons."""

from __future__ import annotations

import asyncio
import time

import pytest

from app.infra.viser_internals import HIDDEN_LABEL, SHOWN_LABEL
from lab_modules.exercises import SCOPE
from tests.wsclient import lab_process, lab_tab, run_async

pytestmark = pytest.mark.classroom

CHART = "Rotor position [µm]"


def _chart_updates(tab, chart: str, since: float) -> int:
    return len(tab.update_times(chart, "data", since))


def test_a_hidden_scope_gets_no_chart_updates_and_the_whole_window_on_return(tmp_path):
    port = 8947
    with lab_process(port, data_dir=tmp_path, log=tmp_path / "server.log"):
        async def scenario():
            tab = await lab_tab(port)
            chart = tab.find("GuiUplotMessage", CHART)
            await asyncio.sleep(1.0)
            shown = tab.find("GuiButtonMessage", f"{SHOWN_LABEL} {SCOPE}")
            hidden = tab.find("GuiButtonMessage", f"{HIDDEN_LABEL} {SCOPE}")
            streaming = _chart_updates(tab, chart, time.perf_counter() - 1.0)
            await tab.set_value(hidden, True)
            await asyncio.sleep(0.5)                              # what was on its way
            quiet_from = time.perf_counter()
            await asyncio.sleep(2.0)
            while_hidden = _chart_updates(tab, chart, quiet_from)
            back_at = time.perf_counter()
            await tab.set_value(shown, True)
            assert await tab.wait_for(lambda: _chart_updates(tab, chart, back_at), 5)
            back_after_s = tab.update_times(chart, "data", back_at)[0] - back_at
            await tab.set_value(hidden, True)                  # hidden while it runs, then paused
            await asyncio.sleep(1.0)
            await tab.set_value(tab.find("GuiButtonGroupMessage", "Simulation"), "Pause")
            await asyncio.sleep(1.0)
            paused_back_at = time.perf_counter()
            await tab.set_value(shown, True)
            paused_back = await tab.wait_for(lambda: _chart_updates(tab, chart, paused_back_at), 3)
            await tab.close()
            return streaming, while_hidden, back_after_s, paused_back
        streaming, while_hidden, back_after_s, paused_back = run_async(scenario())
    print(f"\nchart updates in the last second shown: {streaming}; in 2 s hidden: {while_hidden}; "
          f"first update {back_after_s * 1e3:.0f} ms after the Scope came back")
    assert streaming >= 10 and while_hidden == 0
    assert back_after_s < 0.5
    assert paused_back            # the window it left out while hidden, though paused now
