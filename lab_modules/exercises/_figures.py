"""Figures that back an exercise's claims in ``python -m app reproduce --html``.

Exercises build them in ``report_figures`` from their own scope charts
(``scope_figure``: a headless run drawn like the browser's scope, ±3σ bands
included) and Analysis plots (``plot_figure``).  Only ``matplotlib.figure``
is used (no pyplot), so the caller chooses the backend (Agg in the report).
"""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from lab_modules.exercises import Analysis, Chart, Exercise, Plot

MAX_POINTS = 4000                  # samples drawn per line (every k-th sample beyond)
WIDTH_IN = 9.0                     # figure width [inch] at 100 dpi: fits a 1366 px screen with the table
ROW_HEIGHT_IN = 2.4
BAND_ALPHA = 0.25


def plot_figure(plot: Plot) -> Figure:
    """One of the lab's static ``Plot``s (Analysis tab) drawn by matplotlib."""
    figure = Figure(figsize=(WIDTH_IN, 3.4), layout="constrained")
    axes = figure.add_subplot()
    for label, y, color in plot.series:
        style = {"marker": ".", "linestyle": "none"} if plot.points else {}
        axes.plot(plot.x, y, color=color, label=label, **style)
    if plot.log_x:
        axes.set_xscale("log")
    if plot.log_y:
        axes.set_yscale("log")
    axes.set(title=plot.title, xlabel=plot.x_label, ylabel=plot.y_label)
    axes.grid(True, alpha=0.3)
    if len(plot.series) > 1:
        axes.legend(fontsize="small")
    return figure


def analysis_plots(exercise: Exercise, values: dict, titles: tuple[str, ...] = ()) -> list[Plot]:
    """The Analysis tab's plots of the fullest analysis (only those whose title
    starts with one of ``titles``, in that order, when given)."""
    result = exercise.analyse(values)
    analysis = result if isinstance(result, Analysis) else list(result)[-1]
    if not titles:
        return list(analysis.plots)
    return [plot for title in titles for plot in analysis.plots if plot.title.startswith(title)]


def draw_chart(axes, chart: Chart, trace: np.ndarray, columns: dict[str, int]) -> None:
    """One scope chart on ``axes``: its series over time [s] (column 0 of ``trace``; ``columns``
    maps names to trace columns), scaled to the chart's unit, with the ±3σ band if it has one."""
    t = trace[:, 0]
    if chart.band is not None:
        centre, sigma = chart.band
        scale = next((s.scale for s in chart.series if s.column == centre), chart.series[0].scale)
        mid, width = trace[:, columns[centre]] * scale, 3.0 * trace[:, columns[sigma]] * scale
        axes.fill_between(t, mid - width, mid + width, color="#ff9896", alpha=BAND_ALPHA,
                          linewidth=0, label="±3σ")
    for series in chart.series:
        axes.plot(t, trace[:, columns[series.column]] * series.scale, color=series.color,
                  linewidth=0.8, label=series.label)
    axes.grid(True, alpha=0.3)


def scope_figure(exercise: Exercise, runs: list[tuple[str, dict]], duration_s: float, title: str,
                 charts: tuple[str, ...] = (), window_s: float | None = None) -> Figure:
    """The scope of headless runs side by side: one column per (label, values) run,
    one row per chart (``charts``: titles to keep; all by default), the last
    ``window_s`` seconds (all by default).  Rows share their y axis."""
    shown = [chart for chart in exercise.charts if not charts or chart.title in charts]
    traces = []
    for _, values in runs:
        simulation = exercise.simulation(values)
        trace = simulation.advance(round(duration_s / simulation.sample_time_s))
        if window_s is not None and len(trace):
            trace = trace[trace[:, 0] >= trace[-1, 0] - window_s]
        step = max(1, len(trace) // MAX_POINTS)
        traces.append((trace[::step], {name: 1 + i for i, name in enumerate(simulation.columns)}))
    figure = Figure(figsize=(WIDTH_IN, ROW_HEIGHT_IN * len(shown) + 0.6), layout="constrained")
    grid = figure.subplots(len(shown), len(runs), squeeze=False, sharex="col", sharey="row")
    figure.suptitle(title)
    for row, chart in enumerate(shown):
        for col, ((label, _), (trace, columns)) in enumerate(zip(runs, traces)):
            axes = grid[row, col]
            draw_chart(axes, chart, trace, columns)
            if row == 0:
                axes.set_title(f"{chart.title}: {label}" if label else chart.title, fontsize="medium")
            else:
                axes.set_title(chart.title, fontsize="medium")
            if col == 0:
                axes.set_ylabel(f"{chart.title} [{chart.unit}]" if len(chart.title) < 24 else f"[{chart.unit}]")
            if row == len(shown) - 1:
                axes.set_xlabel("time [s]")
            if col == len(runs) - 1:
                axes.legend(fontsize="x-small", loc="upper right")
    return figure
