"""Live views of the running simulation: an exercise's ``live_plots`` (e.g. the PWM
ripple zoom of self_sensing) and the simulation's speed.

Live plots are drawn on the Scope tab above the scope, at most every
``LIVE_PERIOD_S`` and only when the simulation moved on (a paused run sends
nothing).  Like the scope, their data go out as float32 straight to the wire,
and their axes hold still without touching the chart's options (a changed
scale or series makes viser rebuild the chart, which now and then came up
without axes or lines): the x values span a fixed extent, the y range of
``scope.StickyRange`` is spanned by invisible data (and ``scope.LAYOUT_SERIES``
lays the axes out with every draw) and the plot's own series
take no part in uPlot's auto range (a NaN gap, e.g. outside a fit window,
would spoil it).  ``Plot.shade`` intervals
are a band between two series, the top of the y range inside an interval (its
bottom elsewhere) and its bottom: together they also span the range; a plot
without intervals gets the scope's anchor series instead.  The options are
sent again only when the x extent or the title changes (e.g. a new T_pwm).
"""

from __future__ import annotations

import numpy as np
import viser

from app.infra.viser_internals import send_data
from app.panels import scope
from lab_modules.exercises import Exercise, Plot

LIVE_PERIOD_S = 0.25              # live plots: at most 4 updates/s (self_sensing: ~14 kB per update)
LIVE_ASPECT = 2.2                 # as the scope charts
SHADE_FILL = "rgba(31,119,180,0.12)"
HIDDEN = {"stroke": "rgba(0,0,0,0)", "width": 0, "points": viser.uplot.Series_Points(show=False)}


def _series(plot: Plot) -> tuple[viser.uplot.Series, ...]:
    shade = (viser.uplot.Series(label="LS windows (shaded)", **HIDDEN),
             viser.uplot.Series(label="\u2009", **HIDDEN)) if plot.shade else ()
    anchor = () if plot.shade else (scope.ANCHOR_SERIES,)
    return (viser.uplot.Series(label=plot.x_label), *shade) + tuple(
        viser.uplot.Series(label=label, stroke=color, width=1.5, auto=False,    # the range: shade or anchor
                           points=viser.uplot.Series_Points(show=False))
        for label, _, color in plot.series) + anchor + (scope.LAYOUT_SERIES,)


def chart_data(plot: Plot, range_: tuple[float, float] | None, frame: int = 0) -> tuple[np.ndarray, ...]:
    """The plot's columns: as float32 x, the shade band's two series (if any), the series, the
    anchor's two points (if no shade; ``scope.anchor``), then the layout series' one byte of frame
    number ``frame`` (``scope.layout``); ``range_`` is the y range to hold (None: not yet known)."""
    x = np.asarray(plot.x, dtype=float)
    low, high = range_ if range_ is not None else (0.0, 0.0)
    columns = [x.astype(np.float32)]
    if plot.shade:
        inside = np.zeros(len(x), dtype=bool)
        for start, stop in plot.shade:
            inside |= (x >= start) & (x <= stop)
        columns += [np.where(inside, high, low), np.full(len(x), low)]
    columns += [np.asarray(y, dtype=float) for _, y, _ in plot.series]
    if not plot.shade:
        columns.append(scope.anchor(range_))
    return (*(np.asarray(c, dtype=np.float32) for c in columns), scope.layout(frame))


def _options(plot: Plot) -> dict:
    bands = (viser.uplot.Band(series=(1, 2), fill=SHADE_FILL),) if plot.shade else None
    return {"title": plot.title, "bands": bands, "scales": {"x": viser.uplot.Scale(time=False)},
            **scope.chart_options(plot.x_label, plot.y_label)}


class LivePlots:
    """One exercise's live plots in one tab (none if the exercise has none)."""

    def __init__(self, gui, exercise: Exercise, simulation):
        """Add the charts to the current container (the Scope tab), empty until the first draw."""
        self.exercise = exercise
        plots = exercise.live_plots(simulation)
        self.ranges = [scope.StickyRange() for _ in plots]
        self.shown = [(p.title, float(p.x[0]), float(p.x[-1])) for p in plots]
        self.handles = []
        for plot in plots:
            series = _series(plot)
            self.handles.append(gui.add_uplot(scope.placeholder(float(plot.x[0]), float(plot.x[-1]), len(series) - 1),
                                              series, **_options(plot), aspect=LIVE_ASPECT))
        self.next_draw = 0.0
        self.drawn_until = None
        self.frames = 0

    def draw_next(self) -> None:
        """The next ``draw`` redraws, even at the same newest sample (the plots were left out while hidden)."""
        self.next_draw, self.drawn_until = 0.0, None

    def draw(self, simulation, now: float, newest: float | None) -> None:
        """Redraw from ``simulation`` if ``LIVE_PERIOD_S`` has passed and its newest sample
        time ``newest`` moved on (call holding the tab's ``gui_lock``)."""
        if not self.handles or now < self.next_draw or newest is None or newest == self.drawn_until:
            return
        self.next_draw, self.drawn_until = now + LIVE_PERIOD_S, newest
        self.frames += 1
        for index, (plot, handle) in enumerate(zip(self.exercise.live_plots(simulation), self.handles)):
            y_range = self.ranges[index]
            y_range.update([np.asarray(y, dtype=float) for _, y, _ in plot.series], now)
            data = chart_data(plot, y_range.shown(), self.frames)
            shown = (plot.title, float(plot.x[0]), float(plot.x[-1]))
            if shown != self.shown[index]:            # rare: a new period length or sample time
                self.shown[index] = shown
                handle.title = plot.title
                handle.data = data
                continue
            send_data(handle, data)                     # straight to the wire, as the scope's


class SpeedMeter:
    """Whether the simulation keeps up with the time scale a student asked for, and how much
    room is left: simulated time per wall-clock second (× real time) and the share of one CPU
    core spent computing it (the simulation thread's CPU time per simulated second × simulated
    time per wall-clock second; waits for the GIL and for other threads do not count).  The
    share is what headroom means here: a speed "if computing were all" (simulated time per CPU
    second) read as another speed and swung with the frame's chunk size (kalman_noise at 0.01×:
    "1.9×" of tiny chunks).

    The CPU time is read on one frame in ``TIMED_EVERY`` (``timed()``): reading a thread's
    CPU clock is a system call, not a cheap clock read, and one call per tab and frame
    was a measurable part of a tab's cost; the share over a second is the same."""

    TIMED_EVERY = 8
    KEEPS_UP = 0.95               # shown/asked at or above this: keeping up (frames are 40 ms apart)

    def __init__(self) -> None:
        self.simulated_s = self.computing_s = self.wall_s = self.timed_simulated_s = 0.0
        self.frames = 0

    def timed(self) -> bool:
        """Whether to read the CPU time of this frame's simulation (one frame in ``TIMED_EVERY``)."""
        self.frames += 1
        return self.frames % self.TIMED_EVERY == 1 or self.TIMED_EVERY == 1

    def add(self, simulated_s: float, computing_s: float | None, wall_s: float) -> None:
        """One frame: simulated time, its CPU time (None: not timed), wall-clock time [s]."""
        self.simulated_s += simulated_s
        self.wall_s += wall_s
        if computing_s is not None:
            self.computing_s += computing_s
            self.timed_simulated_s += simulated_s

    def text(self, asked: float = 1.0) -> str:
        """One line over the time since the last call ('' before anything ran); starts afresh.
        ``asked``: the time scale set [× real time]."""
        if self.wall_s <= 0 or self.simulated_s <= 0:
            return ""
        shown = self.simulated_s / self.wall_s
        cpu_per_simulated = self.computing_s / self.timed_simulated_s if self.timed_simulated_s > 0 else 0.0
        busy = 100.0 * cpu_per_simulated * shown
        self.simulated_s = self.computing_s = self.wall_s = self.timed_simulated_s = 0.0
        uses = f"computing uses {busy:.0f} % of one CPU core" if busy >= 1 else "computing uses under 1 % of one CPU core"
        if shown >= self.KEEPS_UP * asked:
            return (f"Simulation: **{shown:.3g}× real time**, keeping up with the time scale ({asked:.3g}×); "
                    f"{uses} ({max(100.0 - busy, 0.0):.0f} % headroom)")
        return (f"Simulation: **{shown:.3g}× real time**, **falling behind** the time scale ({asked:.3g}×); "
                + uses + (" (no headroom)" if busy >= 90 else " (the server is busy with other work)"))
