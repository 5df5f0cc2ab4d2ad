"""The Analysis tab's static plots (``lab_modules.exercises.Plot``) as uPlot charts."""

from __future__ import annotations

import numpy as np
import viser

from app.panels import scope
from lab_modules.exercises import Plot

LOG_SCALE = {"distr": 3, "log": 10}   # uPlot's logarithmic scale
LOG_DECADES = 4                   # a logarithmic plot shows at most this many decades
PLOT_ASPECT = 2.0                 # width / height of an analysis plot


def plot_shape(plot: Plot) -> tuple:
    """What a chart keeps between data updates: title, axes, series and their scales."""
    return (plot.title, plot.x_label, plot.y_label, plot.log_x, plot.log_y, plot.points,
            tuple((label, color) for label, _, color in plot.series))


def plot_chart(plot: Plot) -> tuple[tuple, dict]:
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
    y_span = log_span(*ys, decades=plot.log_decades or LOG_DECADES) if plot.log_y else span(*ys)
    return (x, *ys), {
        "series": series, "title": plot.title, "legend": viser.uplot.Legend(live=False),
        "padding": scope.LOG_X_PADDING if plot.log_x else scope.PADDING,
        "axes": (viser.uplot.Axis(label=plot.x_label),
                 viser.uplot.Axis(label=plot.y_label, **(scope.log_axis(y_span["min"], y_span["max"])
                                                         if plot.log_y else {}))),
        "scales": {"x": viser.uplot.Scale(time=False, range=x_range(x, plot.log_x), **(LOG_SCALE if plot.log_x else {})),
                   "y": viser.uplot.Scale(auto=False, **(LOG_SCALE if plot.log_y else {}), **y_span)}}


def x_range(x: np.ndarray, log: bool) -> tuple[float, float]:
    """The x range a plot holds explicitly: its data, on a logarithmic axis in whole decades.
    Without it viser carries the x range over from the previous data in proportion to the data's
    extent, and when a plot's data changed extent (lqg_vs_pid's fronts: a two-point placeholder,
    then 159 designs) that reached zero or below on a logarithmic axis, where uPlot looks for tick
    marks for a minute and then fails ("Invalid array length", issue 25)."""
    finite = x[np.isfinite(x) & (x > 0)] if log else x[np.isfinite(x)]
    if finite.size == 0:
        return (0.1, 1.0) if log else (0.0, 1.0)
    low, high = float(finite.min()), float(finite.max())
    if log:
        return float(10.0 ** np.floor(np.log10(low))), float(10.0 ** np.ceil(np.log10(high) if high > low else np.log10(low) + 1))
    return (low, high) if high > low else (low - 0.5, high + 0.5)


def log_span(*arrays: np.ndarray, decades: int = LOG_DECADES) -> dict[str, float]:
    """A logarithmic plot range over the positive finite values of ``arrays`` in whole decades,
    at most ``decades`` of them below the largest value."""
    positive = np.concatenate([a[np.isfinite(a) & (a > 0)] for a in arrays]) if arrays else np.zeros(0)
    if positive.size == 0:
        return {"min": 0.1, "max": 1.0}
    top = np.ceil(np.log10(positive.max()))
    return {"min": 10.0 ** max(np.floor(np.log10(positive.min())), top - decades), "max": 10.0**top}


def span(*arrays: np.ndarray) -> dict[str, float]:
    """A plot range covering the finite values of ``arrays`` with a 5 % margin."""
    finite = np.concatenate([a[np.isfinite(a)] for a in arrays]) if arrays else np.zeros(0)
    if finite.size == 0:
        return {"min": -1.0, "max": 1.0}
    low, high = float(finite.min()), float(finite.max())
    margin = 0.05 * (high - low) or 0.05 * max(abs(high), 1.0)
    return {"min": low - margin, "max": high + margin}


class AnalysisPlots:
    """The charts of the Analysis tab (one generation of an exercise)."""

    def __init__(self, gui, container, atomic, plots):
        """Add a chart per plot of ``plots`` (the first result; may be none yet) into ``container``
        (the Analysis tab); ``atomic`` batches a chart's changes into one message (``client.atomic``)."""
        self.gui, self.container, self.atomic = gui, container, atomic
        self.plots, self.plot_shapes = [], []
        for plot in plots:
            data, options = plot_chart(plot)
            self.plots.append(gui.add_uplot(data, **options, aspect=PLOT_ASPECT))
            self.plot_shapes.append(plot_shape(plot))

    def update(self, plots) -> None:
        """Show ``plots`` (call holding the tab's GUI lock).  A later result of ``analyse`` (or the
        margins appended after it) may hold more, fewer or other plots than the first: a chart whose
        plot changed is replaced by a new one in its place (a shown uPlot chart given another plot's
        series and data threw 'Invalid array length' and stopped drawing); missing charts are added
        at the end."""
        for k, plot in enumerate(plots):
            data, options = plot_chart(plot)
            if k >= len(self.plots):
                with self.container:
                    self.plots.append(self.gui.add_uplot(data, **options, aspect=PLOT_ASPECT))
                self.plot_shapes.append(plot_shape(plot))
            elif self.plot_shapes[k] == plot_shape(plot):
                with self.atomic():                   # a log axis's ticks follow its range
                    self.plots[k].data, self.plots[k].scales = data, options["scales"]
                    self.plots[k].axes = options["axes"]
            else:                                     # another plot: a new chart in its place
                with self.atomic(), self.container:
                    replaced = self.plots[k]
                    self.plots[k] = self.gui.add_uplot(data, **options, aspect=PLOT_ASPECT, order=replaced.order)
                    replaced.remove()
                self.plot_shapes[k] = plot_shape(plot)
        for handle in self.plots[len(plots):]:
            handle.remove()
        del self.plots[len(plots):], self.plot_shapes[len(plots):]
