"""What one tab of the default exercise costs on the wire (issue 13: <= 150 kB/s per tab).

Bytes per scope update do not depend on the machine's speed, so this is a test, not a
benchmark: a headless tab (``app.commands.load_bench.Tab``, which decodes everything the lab sends)
watches a lab process in steady state, and everything it received is divided by the scope
updates it got.  At the full 25 updates/s that is the tab's bandwidth.
"""

from __future__ import annotations

import asyncio
import time
from pathlib import Path

from app.commands.lab_processes import lab_server
from app.commands.load_bench import TARGET_BYTES_PER_S, Tab, scope_titles
from app.panels.scope_charts import SCOPE_BUCKETS

FRAME_RATE = 25.0          # scope updates per second a tab gets from an idle server
SETTLE_S = 5.0             # set-up messages and the first analyses are over
WINDOW_S = 5.0
PORT = 8471


async def _steady_state(url: str, titles: tuple[str, ...]) -> tuple[float, float, int]:
    """(bytes of all kinds, bytes of scope-chart updates, scope updates) in ``WINDOW_S`` of steady state."""
    stop = asyncio.Event()
    tab = Tab(url, titles, breakdown=True, slider_every=0)
    task = asyncio.create_task(tab.run(stop))
    try:
        await asyncio.sleep(SETTLE_S)
        deadline = time.perf_counter() + 60
        while not tab.scope_times and time.perf_counter() < deadline:   # a slow machine builds slowly
            await asyncio.sleep(0.5)
        await asyncio.sleep(1.0)
        start_bytes, start_scope, start_updates = tab.received_bytes, tab.kind_bytes["scope chart update"], \
            len(tab.scope_times)
        await asyncio.sleep(WINDOW_S)
        return (tab.received_bytes - start_bytes, tab.kind_bytes["scope chart update"] - start_scope,
                len(tab.scope_times) - start_updates)
    finally:
        stop.set()
        await task


def test_a_tab_of_the_default_exercise_needs_at_most_150_kB_per_s_at_25_updates_per_s(tmp_path: Path):
    with lab_server(PORT, 1, "kalman_noise", tmp_path / "lab.log"):
        total, scope_bytes, updates = asyncio.run(_steady_state(f"ws://127.0.0.1:{PORT}",
                                                                scope_titles("kalman_noise")))
    assert updates >= 10, f"only {updates} scope updates in {WINDOW_S} s"
    per_update, scope_per_update = total / updates, scope_bytes / updates
    print(f"{per_update / 1e3:.2f} kB per scope update ({scope_per_update / 1e3:.2f} kB scope data): "
          f"{per_update * FRAME_RATE / 1e3:.0f} kB/s at {FRAME_RATE:.0f}/s")
    assert per_update * FRAME_RATE <= TARGET_BYTES_PER_S
    # The two charts' data: per chart at most 2 * SCOPE_BUCKETS + 3 points of time, band (2) and
    # series (3, 1) as float32, plus the anchor's two points and the layout byte (scope.anchor/layout)
    # and ~100 bytes of message each.  Full anchor and layout columns (the earlier wire format)
    # would add ~1.5 kB.
    points = 2 * SCOPE_BUCKETS + 3
    budget = sum(4 * points * (1 + columns) + 8 + 8 + 100 for columns in (5, 1))
    assert scope_per_update <= budget, (scope_per_update, budget)
