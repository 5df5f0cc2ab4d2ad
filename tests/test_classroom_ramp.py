"""A class arriving: ~60 headless tabs open one after another on one lab process (loopback,
bounded in count and time); every tab's scope starts within its first seconds and none stalls
(``load_bench.Tab.stall``: no scope update for more than ``STALL_S``, or the tab ended).  On a
machine so busy that every tab waits that long (at load 25 on the 2 cores a tab's first scope
update came 9-34 s after it opened, and then ~1 a second), a tab is late or stalled when it waits
``BUSY_FACTOR`` times as long as the median tab: a slow server slows all tabs alike, a silent
connection only its own.

A silent connection (issue 23: viser's writer lost its wake-up, ``traffic.LoopSideEvent``) was a
rare race, a few times an hour of ramps: this test would meet it by chance only;
``tests/test_traffic.py`` provokes it every time.  Figures are printed (``pytest -s``)."""

from __future__ import annotations

import asyncio
import statistics
import time
from pathlib import Path

import pytest

from app.commands.lab_processes import lab_server
from app.commands.load_bench import STALL_S, Tab, scope_titles
from tests.wsclient import run_async

pytestmark = pytest.mark.classroom

PORT = 8131
TABS = 60
CONNECT_EVERY_S = 0.25        # a class arriving: 4 new tabs a second
FIRST_UPDATE_S = 20.0         # a tab's first scope update comes within this of its opening ...
WATCH_S = 8.0                 # ... and then it is watched at least this long
BUSY_FACTOR = 3.0
SILENT_S = 90.0               # a tab without any scope update this long after opening never gets one


async def _ramp(url: str, titles: tuple[str, ...]) -> tuple[list[tuple[Tab, float]], float]:
    """Open ``TABS`` tabs in a ramp; once every tab has streamed ``WATCH_S`` after its first scope
    update (or waited ``SILENT_S`` for it), return each with the time it was opened, and the end
    of the watch."""
    stop = asyncio.Event()
    opened: list[tuple[Tab, float]] = []
    tasks = []
    try:
        for _ in range(TABS):
            tab = Tab(url, titles, slider_every=0)
            opened.append((tab, time.perf_counter()))
            tasks.append(asyncio.create_task(tab.run(stop)))
            await asyncio.sleep(CONNECT_EVERY_S)

        def done(tab: Tab, at: float) -> bool:
            now = time.perf_counter()
            return (tab.closed is not None or now > at + SILENT_S
                    or bool(tab.scope_times) and now > tab.scope_times[0] + WATCH_S)
        while not all(done(tab, at) for tab, at in opened):
            await asyncio.sleep(0.25)
        return opened, time.perf_counter()
    finally:
        stop.set()
        await asyncio.gather(*tasks, return_exceptions=True)


def _limit(figures: list[float], floor_s: float) -> float:
    """The wait above which a tab is late or stalled: ``floor_s``, or on a busy machine
    ``BUSY_FACTOR`` times the median tab's."""
    return max(floor_s, BUSY_FACTOR * statistics.median(figures)) if figures else floor_s


def test_every_tab_of_a_ramp_streams_from_its_first_seconds_and_none_stalls(tmp_path: Path):
    with lab_server(PORT, 1, "kalman_noise", tmp_path / "lab.log"):
        began = time.perf_counter()
        opened, ended = run_async(_ramp(f"ws://127.0.0.1:{PORT}", scope_titles("kalman_noise")))
    silent = {number: tab.closed for number, (tab, _) in enumerate(opened, 1) if not tab.scope_times}
    assert not silent, f"tabs that never got a scope update (and why they ended): {silent}"
    starts = {number: tab.scope_times[0] - at for number, (tab, at) in enumerate(opened, 1)}
    gaps = [tab.longest_gap(tab.scope_times[0], ended)[0] for tab, _ in opened]
    rates = [len(tab.scope_times) / (ended - tab.scope_times[0]) for tab, _ in opened]
    first_limit_s, stall_limit_s = _limit(list(starts.values()), FIRST_UPDATE_S), _limit(gaps, STALL_S)
    print(f"{TABS} tabs in {ended - began:.0f} s: first scope update {min(starts.values()):.1f}-"
          f"{max(starts.values()):.1f} s after opening (median {statistics.median(starts.values()):.1f} s); "
          f"then scope updates/s min {min(rates):.1f}, median {statistics.median(rates):.1f}; longest wait "
          f"median {statistics.median(gaps):.2f} s, max {max(gaps):.2f} s")
    late = {number: round(start, 1) for number, start in starts.items() if start > first_limit_s}
    assert not late, f"tabs whose first scope update came later than {first_limit_s:.0f} s: {late}"
    stalls = {number: why for number, (tab, _) in enumerate(opened, 1)
              if (why := tab.stall(tab.scope_times[0], ended, stall_limit_s))}
    assert not stalls, f"tabs that stalled (no scope update for more than {stall_limit_s:.1f} s): {stalls}"
