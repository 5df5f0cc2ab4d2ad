"""One browser tab's lab: its own exercise, simulation, parameters, seed and views.

A ``LabSession`` builds the GUI of an exercise generically from the
exercise's parameters, charts, analysis and optional 3D scene, runs the
simulation on its own thread (the compiled loops release the GIL, so tabs run
in parallel) and stops everything when the tab closes.  The exercise chooser
at the top swaps the whole lab for another exercise.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import viser

from lab_modules.exercises import Analysis, Chart, Exercise, Plot, registry
from lab_modules.parameters import Parameter, ParameterError

STATIC = Path(__file__).resolve().parent.parent / "static"
FRAME_S = 1 / 25                  # display refresh
SCOPE_WINDOW_S = 0.05             # simulated time shown on the scope (at the slowest time scale)
SCOPE_POINTS = 500                # points sent per series per frame
SCOPE_ROWS = 20_000               # most samples the scope keeps
POLE_COLORS = ("#7f7f7f", "#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e")


def _format(value: float) -> str:
    if np.isnan(value):
        return "…"
    if np.isinf(value):
        return "∞ (unstable)"
    return f"{value:.3g}" if abs(value) < 1e4 else f"{value:.3e}"


def _analyses(result: Analysis | Iterator[Analysis]) -> Iterator[Analysis]:
    """An exercise's ``analyse`` returns one ``Analysis`` or yields a quick one, then fuller ones."""
    return iter((result,)) if isinstance(result, Analysis) else result


class LabSession:
    """The lab in one browser tab."""

    def __init__(self, client: viser.ClientHandle, exercise: Exercise):
        self.client = client
        self.exercises = registry()
        self.lock = threading.Lock()
        self.closed = False
        self.panel = None
        self.thread: threading.Thread | None = None
        client.gui.configure_theme(dark_mode=False, show_logo=False, control_width="large")
        self._start(exercise)

    # -- life cycle ------------------------------------------------------------------
    def _start(self, exercise: Exercise) -> None:
        self.exercise = exercise
        self.values = exercise.resolve({})
        self.running = True
        self.stopped = False                          # this exercise's thread should end
        self.simulation = exercise.simulation(self.values)
        self.columns = {name: 1 + i for i, name in enumerate(self.simulation.columns)}
        self.buffer = np.empty((0, 1 + len(self.columns)))
        self.analysis_version = 0
        self.scene = exercise.scene(self.values)
        self._build_gui()
        if self.scene is not None:
            self.scene.attach(self.client.scene)
        self._request_analysis()
        self.thread = threading.Thread(target=self._run, name=f"lab-{self.client.client_id}", daemon=True)
        self.thread.start()

    def _switch(self, title: str) -> None:
        chosen = next(e for e in self.exercises.values() if e.title == title)
        if chosen is self.exercise:
            return
        self.stopped = True
        if self.thread is not None:
            self.thread.join(timeout=2.0)
        if self.panel is not None:
            self.panel.remove()
        self.client.gui.reset()
        self.client.scene.reset()
        self._start(chosen)

    def close(self) -> None:
        """Stop the simulation thread; the tab is gone."""
        self.closed = self.stopped = True

    # -- GUI ---------------------------------------------------------------------
    def _build_gui(self) -> None:
        gui = self.client.gui
        titles = tuple(e.title for e in self.exercises.values())
        chooser = gui.add_dropdown("Exercise", titles, initial_value=self.exercise.title,
                                   hint="Switch this tab to another exercise (starts it on its defaults).")
        chooser.on_update(lambda _event: self._switch(chooser.value))
        gui.add_markdown(f"### {self.exercise.title}")
        self.status = gui.add_markdown("**Running**")
        buttons = gui.add_button_group("Simulation", ("Run", "Pause", "Reset"))
        buttons.on_click(lambda event: self._on_button(event.target.value))
        if self.exercise.data_description:
            upload = gui.add_upload_button("Load recording (CSV)", icon=viser.Icon.UPLOAD, mime_type=".csv,text/csv",
                                           hint=self.exercise.data_description)
            upload.on_upload(lambda _event: self._on_upload(upload.value))
        self.inputs: dict[str, viser.GuiInputHandle] = {}
        groups: dict[str, list[Parameter]] = {}
        for parameter in self.exercise.parameters:
            groups.setdefault(parameter.group, []).append(parameter)
        for index, (group, parameters) in enumerate(groups.items()):
            with gui.add_folder(group, expand_by_default=index == 0 or group in ("Controller", "Run")):
                for parameter in parameters:
                    self.inputs[parameter.name] = self._add_input(parameter)
        self.error = gui.add_markdown("")

        first = next(_analyses(self.exercise.analyse(dict(self.values))))
        self.panel = panel = gui.add_panel()
        with panel.add_tab("Scope", viser.Icon.WAVE_SINE):
            self.charts = [self._add_chart(chart) for chart in self.exercise.charts]
            self.readouts = gui.add_markdown("*computing …*")
        with panel.add_tab("Pole map", viser.Icon.CHART_DOTS):
            data, options = self._pole_chart(first.poles)
            self.pole_plot = gui.add_uplot(data, **options, aspect=1.3)
            gui.add_markdown("Poles in the s-plane (discrete poles mapped by s = ln z / T). "
                             "Right of the imaginary axis: unstable.")
            self.pole_table = gui.add_markdown("")
        if first.plots:
            with panel.add_tab("Analysis", viser.Icon.CHART_LINE):
                self.plots = []
                for plot in first.plots:
                    data, options = self._plot_chart(plot)
                    self.plots.append(gui.add_uplot(data, **options, aspect=2.0))
        else:
            self.plots = []
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

    def _add_chart(self, chart: Chart):
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

    @staticmethod
    def _plot_chart(plot: Plot) -> tuple[tuple, dict]:
        """uPlot arguments of a static analysis plot.  uPlot cannot range over
        NaN gaps, so the y scale gets an explicit range from the finite data."""
        x = np.asarray(plot.x, dtype=float)
        ys = [np.asarray(y, dtype=float) for _, y, _ in plot.series]
        series = (viser.uplot.Series(label=plot.x_label),) + tuple(
            viser.uplot.Series(label=label, stroke=color, width=0,
                               points=viser.uplot.Series_Points(show=True, size=8, fill=color, stroke=color))
            if plot.points else
            viser.uplot.Series(label=label, stroke=color, width=1.5, points=viser.uplot.Series_Points(show=False))
            for label, _, color in plot.series)
        return (x, *ys), {
            "series": series, "title": plot.title,
            "axes": (viser.uplot.Axis(label=plot.x_label), viser.uplot.Axis(label=plot.y_label)),
            "scales": {"x": viser.uplot.Scale(time=False), "y": viser.uplot.Scale(auto=False, **_span(*ys))}}

    @staticmethod
    def _pole_chart(poles: dict[str, np.ndarray]) -> tuple[tuple, dict]:
        """The pole map as a scatter plot: one shared, sorted real axis, each
        pole set a series with gaps where the other sets have their poles."""
        points = sorted((p.real, p.imag, index) for index, ps in enumerate(poles.values()) for p in ps)
        x = np.array([p[0] for p in points]) if points else np.zeros(1)
        columns = [np.full(len(x), np.nan) for _ in poles]
        for row, (_, imag, which) in enumerate(points):
            columns[which][row] = imag
        plot = Plot("Poles [rad/s]", "Re s [rad/s]", "Im s [rad/s]", x,
                    tuple((name, column, POLE_COLORS[i % len(POLE_COLORS)])
                          for i, (name, column) in enumerate(zip(poles, columns))), points=True)
        return LabSession._plot_chart(plot)

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
        self._request_analysis()                      # readouts first: they are what the student watches
        with self.lock:
            if parameter.name == "seed":
                self._reset()
            else:
                self.simulation = self.exercise.retune(self.simulation, self.values)
        if self.scene is not None:
            self.scene.update(dict(self.values))

    def _on_upload(self, uploaded) -> None:
        try:
            data = self.exercise.load_data(uploaded.name, uploaded.content)
        except ParameterError as error:
            self.error.content = f"⚠️ {uploaded.name}: {error}"
            return
        self.error.content = f"Loaded {uploaded.name}."
        with self.lock:
            self.values["data"] = data
            self._reset()
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

    # -- analysis (readouts, pole map, plots) -----------------------------------
    def _request_analysis(self) -> None:
        self.analysis_version += 1
        threading.Thread(target=self._analyse, args=(self.analysis_version, dict(self.values)),
                         daemon=True).start()

    def _analyse(self, version: int, values: dict) -> None:
        for result in _analyses(self.exercise.analyse(values)):
            if version != self.analysis_version or self.stopped:
                return                                # a newer slider move supersedes this one
            self._show(result)

    def _show(self, result: Analysis) -> None:
        lines = ["| quantity | value | unit |", "|---|---:|---|"]
        lines += [f"| {label} | {_format(value)} | {unit} |" for label, value, unit in result.readouts]
        with self.lock:
            trace = {name: self.buffer[:, column] for name, column in self.columns.items()}
        if len(self.buffer) >= 10:
            lines += [f"| {label} (scope window) | {_format(value)} | {unit} |"
                      for label, value, unit in self.exercise.live_readouts(trace)]
        self.readouts.content = "\n".join(lines) + "\n\n" + "\n\n".join(f"*{n}*" for n in result.notes)
        self.client.flush()                           # the readouts go out now, not with the next window
        data, options = self._pole_chart(result.poles)
        self.pole_plot.data, self.pole_plot.scales = data, options["scales"]
        rows = ["| set | Re s [rad/s] | Im s [rad/s] | damping ζ |", "|---|---:|---:|---:|"]
        for name, poles in result.poles.items():
            for pole in sorted((p for p in poles if p.imag >= 0), key=lambda p: -p.real):
                zeta = -pole.real / abs(pole) if abs(pole) > 0 else 1.0
                rows.append(f"| {name} | {pole.real:.0f} | {pole.imag:.0f} | {zeta:.2f} |")
        self.pole_table.content = "\n".join(rows)
        for handle, plot in zip(self.plots, result.plots):
            data, options = self._plot_chart(plot)
            handle.data, handle.scales = data, options["scales"]

    # -- simulation thread -------------------------------------------------------------
    def _run(self) -> None:
        carry, last = 0.0, time.perf_counter()
        T = self.simulation.sample_time_s
        while not self.stopped:
            time.sleep(FRAME_S)
            now = time.perf_counter()
            elapsed, last = now - last, now
            if self.scene is not None:
                self.scene.animate(now, self._latest())
            with self.lock:
                if not self.running:
                    continue
                time_scale = self.values.get("time_scale", 1.0)
                carry += time_scale * elapsed / T
                steps, carry = int(carry), carry - int(carry)
                trace = self.simulation.advance(steps)
                window = min(max(int(SCOPE_WINDOW_S * max(time_scale / 0.01, 1.0) / T), 2), SCOPE_ROWS)
                self.buffer = np.concatenate([self.buffer, trace])[-window:]
                message = self.simulation.status_message()
                if message:
                    self.running = False
            self._draw()
            if message:
                self.status.content = f"**Paused — {message}**"
                self.client.add_notification("Simulation stopped", message, color="red",
                                             auto_close_seconds=10.0)

    def _latest(self) -> dict[str, float]:
        """The newest sample of the scope buffer by column name (empty before the first)."""
        buffer = self.buffer
        if len(buffer) == 0:
            return {}
        row = buffer[-1]
        return {"time_s": float(row[0]), **{name: float(row[column]) for name, column in self.columns.items()}}

    def _draw(self) -> None:
        with self.lock:
            buffer = self.buffer
        if len(buffer) < 2:
            return
        rows = buffer[:: max(1, len(buffer) // SCOPE_POINTS)]
        t_ms = rows[:, 0] * 1e3
        for chart, handle in zip(self.exercise.charts, self.charts):
            columns = [t_ms]
            if chart.band:
                centre, sigma = rows[:, self.columns[chart.band[0]]], rows[:, self.columns[chart.band[1]]]
                scale = chart.series[0].scale
                columns += [(centre + 3 * sigma) * scale, (centre - 3 * sigma) * scale]
            columns += [rows[:, self.columns[s.column]] * s.scale for s in chart.series]
            handle.data = tuple(columns)


def _span(*arrays: np.ndarray) -> dict[str, float]:
    """A plot range covering the finite values of ``arrays`` with a 5 % margin."""
    finite = np.concatenate([a[np.isfinite(a)] for a in arrays]) if arrays else np.zeros(0)
    if finite.size == 0:
        return {"min": -1.0, "max": 1.0}
    low, high = float(finite.min()), float(finite.max())
    margin = 0.05 * (high - low) or 0.05 * max(abs(high), 1.0)
    return {"min": low - margin, "max": high + margin}
