"""The app's live views without a browser: exercise actions run in the background
(``app/panels/actions.py``), live plots drawn at a bounded rate and size (``app/panels/live.py``),
the simulation-speed readout."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from app.panels.actions import ActionPanel, result_markdown
from app.panels.live import LIVE_PERIOD_S, LivePlots, SpeedMeter, chart_data
from lab_modules.exercises import Action, Analysis, Exercise, Plot, get


class FakeHandle:
    def __init__(self, data=None, **options):
        self.sent, self.order = [], options.get("order", 0.0)
        self.content, self.data, self.title = "", data, options.get("title")
        self._impl = type("Impl", (), {"props": type("Props", (), {})()})()

    def _queue_update(self, name, value):
        self.sent.append(value)

    def on_click(self, callback):
        self.clicked = callback


class FakeGui:
    def __init__(self):
        self.handles = []

    def _add(self, *args, **options):
        handle = FakeHandle(args[0] if args else None, **options)
        self.handles.append(handle)
        return handle

    add_uplot = add_button = add_markdown = _add


class FakeSession:
    """What ActionPanel uses of a LabSession."""

    def __init__(self, exercise, values):
        self.exercise, self.values, self.generation, self.closed = exercise, values, 0, False
        self.lock, self.gui_lock = threading.Lock(), threading.RLock()
        self.analysis_wakeup = threading.Condition()
        self.budget = type("Budget", (), {"charge": lambda self, cpu_s: 0.0})()
        self.client = type("Client", (), {"client_id": 0, "flush": lambda self: None})()

    def _on(self, key, action):
        return lambda _event=None: action()

    def _current(self, generation):
        return generation == self.generation and not self.closed

    def pace(self, cpu_s):
        pass

    def action_panel(self, gui, plot_chart):
        """The panel as the tab builds it, for the generation shown now."""
        generation = self.generation
        return ActionPanel(gui, self.exercise, self._on, lambda: dict(self.values),
                           lambda: self._current(generation), self.gui_lock, self, self.client, plot_chart)


def _plot_chart(plot: Plot):
    return (plot.x, *(y for _, y, _ in plot.series)), {"scales": {}, "title": plot.title}


class Slow(Exercise):
    """An exercise whose action yields three steps, slowly."""

    name, title, parameters, charts = "slow", "Slow", (), ()
    actions = (Action("Go", "go"),)

    def __init__(self):
        self.release = threading.Event()              # the action waits for the test to let it go

    def go(self, values):
        self.release.wait(timeout=10)
        for k in range(3):
            time.sleep(0.05)
            yield Analysis([("step", k, "")], {}, [f"step {k + 1} of 3"],
                           [Plot("p", "x [1]", "y [1]", np.arange(3.0), (("y", np.full(3, k), "#000"),))])


def _wait_for(predicate, timeout_s=10.0):
    deadline = time.time() + timeout_s
    while not predicate() and time.time() < deadline:
        time.sleep(0.01)
    return predicate()


def test_an_action_runs_in_the_background_and_shows_progress_then_its_result():
    exercise = Slow()
    session = FakeSession(exercise, {})
    gui = FakeGui()
    panel = session.action_panel(gui, _plot_chart)
    button, text = gui.handles
    button.clicked()                                  # returns while the action still waits: it runs elsewhere
    assert not exercise.release.is_set() and "step" not in text.content
    exercise.release.set()
    assert _wait_for(lambda: "step 3 of 3" in text.content)
    assert "⏳" not in text.content and "| step | 2 |" in text.content
    plots = panel.plots["Go"]
    assert len(plots) == 1 and plots[0].order > text.order         # right below the result text
    assert np.all(plots[0].data[1] == 2)                            # the last step's plot


def test_a_switched_exercise_stops_its_action():
    exercise = Slow()
    session = FakeSession(exercise, {})
    gui = FakeGui()
    session.action_panel(gui, _plot_chart)
    button, text = gui.handles
    button.clicked()
    session.generation = 1
    exercise.release.set()                                          # the tab switched exercises
    time.sleep(0.4)
    assert "step" not in text.content


def test_result_markdown_marks_a_running_action():
    result = Analysis([("ratio", 1.0043, "")], {}, ["2 of 4 seeds done"])
    assert "⏳ **2 of 4 seeds done**" in result_markdown(result, running=True)
    assert "| ratio | 1.004 |" in result_markdown(result, running=False)


def test_self_sensing_monte_carlo_button_holds_its_claim():
    """The button's result: MC std / predicted σ̂(L̄) within [0.95, 1.05] over 5000 periods at 4 mm,
    ≥ 99.5 % inside ±3σ̂ (paper 001 §5, Fig. 6), with progress after every seed."""
    exercise = get("self_sensing")
    steps = list(exercise.monte_carlo(exercise.resolve({})))
    assert len(steps) == 1 + 4
    assert "seed 1 of 4" in steps[0].notes[0]
    final = {label: value for label, value, _ in steps[-1].readouts}
    assert 0.95 <= final["MC std of L̄ − L / predicted σ̂(L̄)"] <= 1.05
    assert final["Share of L̄ − L inside ±3σ̂(L̄)"] >= 99.5
    assert final["Periods"] == 5000
    assert "4 mm" in steps[-1].plots[0].title
    fixed_6 = list(exercise.monte_carlo(exercise.resolve({"trajectory": "fixed at gap 2"}), seeds=1, periods=200))
    assert "6 mm" in fixed_6[-1].notes[0]


def test_live_ripple_zoom_of_the_running_simulation():
    """The newest two PWM periods: every 8th sample, the LS windows of the loop's own duty,
    fitted lines only inside them, and slopes that give the inductance the loop estimated."""
    exercise = get("self_sensing")
    values = exercise.resolve({"sigma_current_ma": 0.0, "sigma_voltage_mv": 0.0, "trajectory": "fixed at gap 1"})
    simulation = exercise.simulation(values)
    rows = simulation.advance(50)[:, 1:]
    current, voltage = exercise.live_plots(simulation)
    assert len(current.x) == 256 and current.x[-1] == pytest.approx(2040.0)      # µs: every 8th of 2 × 1024 samples
    n_on = round(rows[-1, list(simulation.columns).index("duty")] * 1024)
    assert current.shade[-2] == pytest.approx((1024 + 8, 1024 + n_on - 8))      # phase I window of the newest period
    fit = {label: y for label, y, _ in current.series}["fit I, period 2"]
    inside = np.isfinite(fit)
    x = current.x[inside]
    assert np.all((x >= current.shade[-2][0]) & (x <= current.shade[-2][1]))
    slope = np.polyfit(x * 1e-6, fit[inside], 1)[0]                 # A/s
    true_i = {label: y for label, y, _ in current.series}["true i"]
    v_eff = 11.4 - 2.5 * np.mean(true_i[inside])
    estimated = rows[-1, list(simulation.columns).index("inductance_1_h")]
    assert abs(v_eff / slope / estimated - 1) < 5e-3
    assert set(np.unique({label: y for label, y, _ in voltage.series}["applied v"])) == {-11.4, 11.4}


def test_live_plot_bandwidth_and_rate():
    """self_sensing's live plots: at most 17 kB of float32 per update (15 columns of 256 points
    and the one byte of ``scope.LAYOUT_SERIES``) and 10 updates/s, so ≤ 68 kB/s per tab at the app's
    4 updates/s (the scope of this exercise sends ~370 kB/s)."""
    exercise = get("self_sensing")
    simulation = exercise.simulation(exercise.resolve({}))
    simulation.advance(10)
    size = sum(column.nbytes for plot in exercise.live_plots(simulation)
               for column in chart_data(plot, (0.0, 1.0)))
    for plot in exercise.live_plots(simulation):
        *columns, layout = chart_data(plot, None)
        assert all(c.dtype == np.float32 for c in columns) and layout.dtype == np.uint8 and len(layout) == 1
    assert LIVE_PERIOD_S >= 0.1
    assert size <= 17_000 and size / LIVE_PERIOD_S <= 68_000, size


def test_live_plots_draw_at_a_bounded_rate_and_only_when_the_run_moved_on():
    exercise = get("self_sensing")
    simulation = exercise.simulation(exercise.resolve({}))
    gui = FakeGui()
    live = LivePlots(gui, exercise, simulation)
    assert len(gui.handles) == 2
    simulation.advance(5)
    live.draw(simulation, 10.0, newest=1.0)                         # drawn
    live.draw(simulation, 10.0 + LIVE_PERIOD_S / 2, newest=2.0)     # too soon
    live.draw(simulation, 10.0 + 2 * LIVE_PERIOD_S, newest=2.0)     # later, and the run moved on: drawn
    live.draw(simulation, 10.0 + 4 * LIVE_PERIOD_S, newest=2.0)     # paused: nothing new
    assert [len(h.sent) for h in gui.handles] == [2, 2]
    _x, top, bottom, *series = gui.handles[0].sent[-1]
    low, high = live.ranges[0].shown()                              # the range itself from the first frame
    assert set(np.unique(top)) == {np.float32(low), np.float32(high)} and np.all(bottom == np.float32(low))
    measured = series[0]
    assert low <= measured.min() and measured.max() <= high
    assert get("kalman_noise").live_plots(get("kalman_noise").simulation(get("kalman_noise").resolve({}))) == []


def test_speed_meter():
    meter = SpeedMeter()
    assert meter.text() == ""
    meter.add(0.01, 0.0005, 0.04)
    meter.add(0.01, 0.0005, 0.04)
    text = meter.text(0.25)                                         # slow motion, asked for
    assert "**0.25× real time**, keeping up with the time scale (0.25×)" in text
    assert "computing uses 1 % of one CPU core (99 % headroom)" in text
    assert "computing alone" not in text and "20×" not in text      # no second, confusing speed
    assert meter.text() == ""                                       # starts afresh
    meter.add(0.03, 0.039, 0.04)                                    # asked 1×, got 0.75×: the CPU is the limit
    text = meter.text(1.0)
    assert "**0.75× real time**, **falling behind** the time scale (1×)" in text and "98 %" in text
    assert "no headroom" in text
    meter.add(0.01, 0.0005, 0.04)                                   # one timed frame, one not (TIMED_EVERY):
    meter.add(0.01, None, 0.04)                                     # the share holds for both
    assert "computing uses 1 % of one CPU core (99 % headroom)" in meter.text(0.25)
