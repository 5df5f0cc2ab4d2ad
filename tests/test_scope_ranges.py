"""The scope's y ranges (app/panels/scope.py, scope_charts.py): they hold still while a run goes
on and close in on the traces once it stops.  maglev_tuning's case: its filter starts from the
paper's P0 = 1e-5 I, so the first sample's ±3√S is ±9.5 mm while the rest of the 6 s recording
is under ±1 mm; the range held the first sample's width after the recording ended."""

from __future__ import annotations

import numpy as np
import pytest
import viser

from app.panels import scope
from app.panels.scope_charts import ScopeCharts
from app.tab.state import LabState
from lab_modules.exercises import get


def test_a_range_holds_still_while_the_traces_shrink_and_fit_closes_in_at_once():
    y_range = scope.StickyRange()
    y_range.follow(-9.5, 9.5, now=0.0)
    wide = y_range.shown()
    assert not y_range.follow(-0.9, 0.9, now=1.0) and y_range.shown() == wide
    assert not y_range.follow(-0.9, 0.9, now=1.0 + scope.SHRINK_AFTER_S / 2) and y_range.shown() == wide
    y_range.fit(-0.9, 0.9)
    assert y_range.shown() == scope.nice_range(-0.9, 0.9) and y_range.shown()[1] < wide[1] / 5


@pytest.fixture(scope="module")
def gui():
    server = viser.ViserServer(host="127.0.0.1", port=8467, verbose=False)
    yield server.gui
    server.stop()


def test_maglev_tunings_innovation_range_fits_the_stopped_recording(gui):
    exercise = get("maglev_tuning")
    state = LabState()
    values = exercise.resolve({})
    state.load(exercise, values, exercise.simulation(values), None)
    charts = ScopeCharts(gui, exercise.charts, state.columns, state.window_ms())
    innovation = [chart.title for chart in exercise.charts].index("Innovation ±3√S")
    now = 0.0
    while not state.simulation.status_message():                       # the whole recording, frame by frame
        state.append(state.simulation.advance(200))
        now += 0.04
        charts.draw(state.buffer, state.simulation.sample_time_s, state.window_ms(), now)
    running = charts.y_ranges[innovation].shown()
    column = state.buffer[:, state.columns["innovation_sigma_m"]]
    shown_band_um = 3 * 1e6 * np.nanmax(column)                          # the band in the stopped window
    assert running[1] > 5 * shown_band_um                                # the first sample's width held on
    assert charts.draw(state.buffer, state.simulation.sample_time_s, state.window_ms(), now, fit=True)
    low, high = charts.y_ranges[innovation].shown()
    assert shown_band_um <= high <= 3 * shown_band_um and low == -high       # round steps, 1.2 headroom
