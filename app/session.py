"""One browser tab's lab: its own simulation, parameters, seed and views.

A ``LabSession`` builds the GUI of an exercise generically from the
exercise's parameters, charts and analysis, runs the simulation on its own
thread (the compiled loop releases the GIL, so tabs run in parallel) and
stops everything when the tab closes.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import numpy as np
import viser

from lab_modules.closed_loop import TRACE_COLUMNS
from lab_modules.exercises import Exercise
from lab_modules.parameters import Parameter, ParameterError

STATIC = Path(__file__).resolve().parent.parent / "static"
FRAME_S = 1 / 25                  # display refresh
SCOPE_WINDOW_S = 0.05             # simulated time shown on the scope
SCOPE_POINTS = 500                # points sent per series per frame
POLE_COLORS = {"open-loop plant": "#7f7f7f", "closed loop": "#1f77b4", "filter error": "#d62728"}


def _format(value: float) -> str:
    if not np.isfinite(value):
        return "∞ (unstable)"
    return f"{value:.3g}" if abs(value) < 1e4 else f"{value:.3e}"


class LabSession:
    """The lab in one browser tab."""

    def __init__(self, client: viser.ClientHandle, exercise: Exercise):
        self.client = client
        self.exercise = exercise
        self.values = exercise.resolve({})
        self.lock = threading.Lock()
        self.running = True
        self.closed = False
        self.simulation = exercise.simulation(self.values)
        self.columns = {name: 1 + i for i, name in enumerate(TRACE_COLUMNS)}
        self.buffer = np.empty((0, len(TRACE_COLUMNS) + 1))
        self.inputs: dict[str, viser.GuiInputHandle] = {}
        self.analysis_version = 0
        self._build_gui()
        self._request_analysis()
        self.thread = threading.Thread(target=self._run, name=f"lab-{client.client_id}", daemon=True)
        self.thread.start()

    # -- GUI ---------------------------------------------------------------------
    def _build_gui(self) -> None:
        gui = self.client.gui
        gui.configure_theme(dark_mode=False, show_logo=False, control_width="large")
        gui.add_markdown(f"### {self.exercise.title}")
        self.status = gui.add_markdown("**Running**")
        buttons = gui.add_button_group("Simulation", ("Run", "Pause", "Reset"))
        buttons.on_click(lambda event: self._on_button(event.target.value))
        groups: dict[str, list[Parameter]] = {}
        for parameter in self.exercise.parameters:
            groups.setdefault(parameter.group, []).append(parameter)
        for group, parameters in groups.items():
            with gui.add_folder(group, expand_by_default=group in ("Noise", "Controller", "Run")):
                for parameter in parameters:
                    self.inputs[parameter.name] = self._add_input(parameter)
        self.error = gui.add_markdown("")

        panel = gui.add_panel()
        with panel.add_tab("Scope", viser.Icon.WAVE_SINE):
            self.charts = [self._add_chart(chart) for chart in self.exercise.charts]
            self.readouts = gui.add_markdown("*computing …*")
        with panel.add_tab("Pole map", viser.Icon.CHART_DOTS):
            self.pole_plot = self._add_pole_plot({})
            gui.add_markdown("Poles in the s-plane (discrete poles mapped by s = ln z / T). "
                             "Right of the imaginary axis: unstable.")
            self.pole_table = gui.add_markdown("")
        with panel.add_tab("Worksheet", viser.Icon.NOTEBOOK):
            gui.add_markdown((STATIC / "worksheets" / self.exercise.worksheet).read_text(encoding="utf-8"))
        panel.dock_right()
        panel.set_width(760)

    def _add_input(self, parameter: Parameter):
        gui, value = self.client.gui, self.values[parameter.name]
        label = f"{parameter.label} [{parameter.unit}]" if parameter.unit else parameter.label
        if parameter.choices:
            handle = gui.add_dropdown(label, parameter.choices, initial_value=value, hint=parameter.description)
        elif parameter.log:
            handle = gui.add_slider(f"log₁₀ {label}", np.log10(parameter.minimum), np.log10(parameter.maximum),
                                    step=0.01, initial_value=float(np.log10(value)), hint=parameter.description)
        elif parameter.integer:
            handle = gui.add_number(label, int(value), min=int(parameter.minimum),
                                    max=int(parameter.maximum), step=1, hint=parameter.description)
        else:
            handle = gui.add_slider(label, parameter.minimum, parameter.maximum,
                                    step=parameter.step or (parameter.maximum - parameter.minimum) / 1000,
                                    initial_value=float(value), hint=parameter.description)
        handle.on_update(lambda _event, p=parameter, h=handle: self._on_input(p, h.value))
        return handle

    def _add_chart(self, chart):
        series = [viser.uplot.Series(label="time [ms]")]
        if chart.band:
            series += [viser.uplot.Series(label="+3σ", stroke="rgba(214,39,40,0.35)", width=1),
                       viser.uplot.Series(label="−3σ", stroke="rgba(214,39,40,0.35)", width=1)]
        series += [viser.uplot.Series(label=s.label, stroke=s.color, width=1.5) for s in chart.series]
        bands = (viser.uplot.Band(series=(1, 2), fill="rgba(214,39,40,0.12)"),) if chart.band else None
        empty = tuple(np.zeros(2) for _ in series)
        return self.client.gui.add_uplot(
            empty, tuple(series), title=f"{chart.title} [{chart.unit}]", bands=bands,
            axes=(viser.uplot.Axis(label="time [ms]"), viser.uplot.Axis(label=f"{chart.title} [{chart.unit}]")),
            scales={"x": viser.uplot.Scale(time=False)}, aspect=3.2)

    def _add_pole_plot(self, poles):
        data, series = self._pole_data(poles)
        return self.client.gui.add_uplot(
            data, series, title="Poles [rad/s]", aspect=1.3,
            scales={"x": viser.uplot.Scale(time=False)},
            axes=(viser.uplot.Axis(label="Re s [rad/s]"), viser.uplot.Axis(label="Im s [rad/s]")))

    @staticmethod
    def _pole_data(poles: dict[str, np.ndarray]):
        """uPlot wants one shared, sorted x: merge all real parts, leave gaps (NaN)."""
        names = list(POLE_COLORS)
        points = [(p.real, p.imag, names.index(n)) for n, ps in poles.items() for p in ps]
        points.sort()
        x = np.array([p[0] for p in points]) if points else np.zeros(1)
        columns = [np.full(len(x), np.nan) for _ in names]
        for row, (_, imag, which) in enumerate(points):
            columns[which][row] = imag
        series = (viser.uplot.Series(label="Re s [rad/s]"),) + tuple(
            viser.uplot.Series(label=name, stroke=POLE_COLORS[name], width=0,
                               points=viser.uplot.Series_Points(show=True, size=9, fill=POLE_COLORS[name]))
            for name in names)
        return (x, *columns), series

    # -- events --------------------------------------------------------------------
    def _on_input(self, parameter: Parameter, shown) -> None:
        value = 10 ** float(shown) if parameter.log else shown
        try:
            value = parameter.parse(value)
        except ParameterError as error:
            self.error.content = f"⚠️ {error}"
            return
        self.error.content = ""
        with self.lock:
            self.values[parameter.name] = value
            if parameter.name == "time_scale":
                return
            if parameter.name == "seed":
                self._reset()
            else:
                self.simulation = self.simulation.retuned(self.exercise.simulation(self.values).setup)
        self._request_analysis()

    def _on_button(self, which: str) -> None:
        with self.lock:
            if which == "Reset" or which == "Run" and self.simulation.status_message():
                self._reset()
            self.running = which != "Pause"
        self.status.content = "**Running**" if self.running else "**Paused**"

    def _reset(self) -> None:
        self.simulation = self.exercise.simulation(self.values)
        self.buffer = self.buffer[:0]

    # -- analysis (readouts, pole map) -----------------------------------------
    def _request_analysis(self) -> None:
        self.analysis_version += 1
        threading.Thread(target=self._analyse, args=(self.analysis_version, dict(self.values)),
                         daemon=True).start()

    def _analyse(self, version: int, values: dict) -> None:
        result = self.exercise.analyse(values)
        if version != self.analysis_version or self.closed:
            return                                    # a newer slider move supersedes this one
        lines = ["| quantity | value | unit |", "|---|---:|---|"]
        lines += [f"| {label} | {_format(value)} | {unit} |" for label, value, unit in result.readouts]
        live = self._live_rms()
        if live is not None:
            lines.append(f"| RMS displacement, this run (scope window) | {live:.3g} | µm |")
        self.readouts.content = "\n".join(lines) + "\n\n" + "\n\n".join(f"*{n}*" for n in result.notes)
        data, _ = self._pole_data(result.poles)
        self.pole_plot.data = data
        rows = ["| set | Re s [rad/s] | Im s [rad/s] | damping ζ |", "|---|---:|---:|---:|"]
        for name, poles in result.poles.items():
            for pole in sorted((p for p in poles if p.imag >= 0), key=lambda p: -p.real):
                zeta = -pole.real / abs(pole) if abs(pole) > 0 else 1.0
                rows.append(f"| {name} | {pole.real:.0f} | {pole.imag:.0f} | {zeta:.2f} |")
        self.pole_table.content = "\n".join(rows)

    def _live_rms(self):
        if len(self.buffer) < 10:
            return None
        return float(np.sqrt(np.mean(self.buffer[:, self.columns["x_true_m"]] ** 2)) * 1e6)

    # -- simulation thread -------------------------------------------------------------
    def _run(self) -> None:
        carry, last = 0.0, time.perf_counter()
        T = self.simulation.setup.rig.sample_time_s
        window = int(SCOPE_WINDOW_S / T)
        while not self.closed:
            time.sleep(FRAME_S)
            now = time.perf_counter()
            elapsed, last = now - last, now
            with self.lock:
                if not self.running:
                    continue
                carry += self.values["time_scale"] * elapsed / T
                steps, carry = int(carry), carry - int(carry)
                trace = self.simulation.advance(steps)
                self.buffer = np.concatenate([self.buffer, trace])[-window:]
                message = self.simulation.status_message()
                if message:
                    self.running = False
            self._draw()
            if message:
                self.status.content = f"**Paused — {message}**"
                self.client.add_notification("Simulation stopped", message, color="red",
                                             auto_close_seconds=10.0)

    def _draw(self) -> None:
        if len(self.buffer) < 2:
            return
        step = max(1, len(self.buffer) // SCOPE_POINTS)
        rows = self.buffer[::step]
        t_ms = rows[:, 0] * 1e3
        for chart, handle in zip(self.exercise.charts, self.charts):
            columns = [t_ms]
            if chart.band:
                centre, sigma = rows[:, self.columns[chart.band[0]]], rows[:, self.columns[chart.band[1]]]
                scale = chart.series[0].scale
                columns += [(centre + 3 * sigma) * scale, (centre - 3 * sigma) * scale]
            columns += [rows[:, self.columns[s.column]] * s.scale for s in chart.series]
            handle.data = tuple(columns)

    def close(self) -> None:
        """Stop the simulation thread; the tab is gone."""
        self.closed = True
