"""The rolling scope charts: fixed axes a student can read by eye.

The time axis is the time before the newest sample and the data always span
exactly the scope window (−window … 0 ms).  Not scrolled: viser's chart keeps
an auto-ranged x scale *relative* to the data's x extent and re-derives that
relation whenever the extent moves (every frame, for absolute times); when a
chart's tab is hidden (width 0) and shown again, that update read uPlot's
placeholder scale [0, 1], so the relation became "a 1 ms window far behind
the data" and stayed so — the blank scope of issue 11, defect 1.  With a
fixed extent the relation is set once, when the chart is made.

The y axis holds still as well (defect 13): a range in round steps that
grows at once when a trace leaves it and shrinks only after the traces have
used less than a third of it for ``SHRINK_AFTER_S``; an invisible anchor
series spans it, so uPlot's own auto range lands on it.
"""

from __future__ import annotations

import math
import time

import numpy as np
import viser

from lab_modules.formatting import SUPERSCRIPT

SHRINK_AFTER_S = 3.0          # a range three times too large for this long shrinks
HEADROOM = 1.2                # the range covers the traces with this factor
PADDING = (12, 16, 0, 4)      # top, right, bottom, left [px]: the top tick label stays inside the chart
#: log-frequency axes end on a decade whose label ("10,000") is centred on the right edge: room for its half
LOG_X_PADDING = (12, 30, 0, 4)
Y_AXIS_SIZE = 56              # px for the y tick labels (five significant characters)
X_AXIS_SIZE = 50              # px for the x tick labels (uPlot's default, fixed: no size from the labels)


def nice_ceiling(value: float) -> float:
    """The smallest of 1, 2, 2.5, 5 × 10^n at or above ``value`` (> 0)."""
    exponent = math.floor(math.log10(value))
    for step in (1.0, 2.0, 2.5, 5.0, 10.0):
        if step * 10.0**exponent >= value * (1 - 1e-12):
            return step * 10.0**exponent
    return 10.0 ** (exponent + 1)


def nice_range(low: float, high: float) -> tuple[float, float]:
    """A range in round numbers around [low, high] with ``HEADROOM``: symmetric about
    zero when the data straddle it, else from the nearest round value below/above."""
    if not (np.isfinite(low) and np.isfinite(high)):
        return (-1.0, 1.0)
    span = max(high - low, 1e-12 * max(abs(high), abs(low)), 1e-30)
    centre = 0.5 * (low + high)
    if low < 0 < high:
        reach = nice_ceiling(HEADROOM * max(-low, high))
        return (-reach, reach)
    step = nice_ceiling(HEADROOM * span / 4)
    lo = math.floor((centre - HEADROOM * span / 2) / step) * step
    hi = math.ceil((centre + HEADROOM * span / 2) / step) * step
    return (lo, hi)


class StickyRange:
    """A y range that only moves when it must (see the module docstring)."""

    def __init__(self) -> None:
        self.range: tuple[float, float] | None = None
        self.loose_since: float | None = None

    def shown(self) -> tuple[float, float] | None:
        """The range the anchor spans this frame (None before the first finite value)."""
        return self.range

    def update(self, columns: list[np.ndarray], now: float | None = None) -> bool:
        """Follow the traces; True if the range changed."""
        finite = np.concatenate([c[np.isfinite(c)] for c in columns]) if columns else np.zeros(0)
        if finite.size == 0:
            return self.follow(math.inf, -math.inf, now)
        return self.follow(float(finite.min()), float(finite.max()), now)

    def fit(self, low: float, high: float) -> None:
        """At once the range that ``follow`` would shrink to (the traces stopped moving)."""
        if low <= high:
            self.range, self.loose_since = nice_range(low, high), None

    def follow(self, low: float, high: float, now: float | None = None) -> bool:
        """``update`` from the lowest and highest finite value drawn (nothing finite: low > high);
        called once per frame."""
        if not low <= high:
            return False
        now = time.perf_counter() if now is None else now
        if self.range is None or low < self.range[0] or high > self.range[1]:
            self.range, self.loose_since = nice_range(low, high), None
            return True
        used = (high - low) / (self.range[1] - self.range[0])
        if used >= 1 / 3 and max(abs(low), abs(high)) >= max(abs(r) for r in self.range) / 3:
            self.loose_since = None
            return False
        if self.loose_since is None:
            self.loose_since = now
            return False
        if now - self.loose_since < SHRINK_AFTER_S:
            return False
        self.range, self.loose_since = nice_range(low, high), None
        return True


#: An invisible series over the sticky range: uPlot's auto range then covers exactly it.  (Changing
#: the scale options instead makes viser rebuild the chart, which now and then came up without axes.)
#: Its legend entry is hidden by ``LEGEND_STYLE`` (uPlot puts a series' ``class`` on its legend row).
ANCHOR_CLASS = "lab-range-anchor"
ANCHOR_SERIES = viser.uplot.Series(label="range", stroke="rgba(0,0,0,0)", width=0,
                                   points=viser.uplot.Series_Points(show=False), **{"class": ANCHOR_CLASS})
#: A hidden series on a scale of its own, whose every frame alternates between two constant values:
#: its scale changes with every frame, and uPlot lays a chart's axes out again whenever one of its
#: scales changes.  Why it is needed (issue 11, defect 13): a panel tab's charts are made anew on
#: every visit (the tab's content is unmounted while hidden), at width 0, and laid out there (no
#: space: no tick labels).  The resize that follows lays them out again, but when it reaches uPlot
#: in the same render as a data update, uplot-react's ``setData(data, false)`` + ``redraw()``
#: resets uPlot's pending layout (``redraw`` sets ``shouldConvergeSize = recalcAxes || false``)
#: and, with x and y ranges that hold still, nothing asks for it again: the axes stayed blank.
#: Fixed axis sizes alone do not help (the tick values are computed in that layout); a y range
#: that moves would (an earlier workaround showed a wider range for the first ~2 s).
LAYOUT_SCALE = "layout"
LAYOUT_SERIES = viser.uplot.Series(label="layout", scale=LAYOUT_SCALE, stroke="rgba(0,0,0,0)", width=0,
                                   points=viser.uplot.Series_Points(show=False), **{"class": ANCHOR_CLASS})


def layout(frame: int) -> np.ndarray:
    """The layout series' one value in frame number ``frame``: 1 or 2, alternately, as one byte.
    A series shorter than the x values is allowed on the wire: uPlot reads the missing points
    as gaps (``undefined == null``), skips them when it ranges a scale and draws nothing there,
    so a hidden series costs one or two points, not a column (issue 13: 1.5 kB less per
    kalman_noise scope update than full columns)."""
    return np.array([1 + frame % 2], dtype=np.uint8)


#: A style element for the page (``gui.add_html``): the anchor series stays out of the legends.
LEGEND_STYLE = f"<style>.u-legend .{ANCHOR_CLASS} {{ display: none; }}</style>"


def anchor(y_range: tuple[float, float] | None) -> np.ndarray:
    """The anchor series' two points: the range's ends (zeros before the first range); the
    points after them are gaps (see ``layout``)."""
    low, high = y_range if y_range is not None else (0.0, 0.0)
    return np.array((low, high), dtype=np.float32)


def placeholder(x_first: float, x_last: float, series: int) -> tuple[np.ndarray, ...]:
    """A chart's data before its first frame: two points over the x extent the chart keeps, and
    zeros for each of its ``series`` y series (viser makes a chart only from equal columns)."""
    return (np.array([x_first, x_last]),) + tuple(np.zeros(2) for _ in range(series))


def chart_options(x_label: str, y_label: str) -> dict:
    """Axes, legend and padding shared by every chart of the lab: static legend (no '--'
    placeholders before a hover), room for the top tick label and for five-character y ticks."""
    return {"axes": (viser.uplot.Axis(label=x_label, size=X_AXIS_SIZE),
                     viser.uplot.Axis(label=y_label, size=Y_AXIS_SIZE)),
            "legend": viser.uplot.Legend(live=False),
            "padding": PADDING}




def decade_label(exponent: int) -> str:
    """10^exponent as a tick label: plain from 0.001 to 1000, else 10⁻⁴, 10⁴ ... (uPlot's own
    numbers keep three decimals, so every decade below 0.001 read "0")."""
    if -3 <= exponent <= 3:
        return f"{10.0 ** exponent:.{max(-exponent, 0)}f}"
    return "10" + str(exponent).translate(SUPERSCRIPT)


def log_axis(low: float, high: float) -> dict:
    """Static ``splits`` and ``values`` of a logarithmic axis over [low, high] (whole decades):
    a labelled tick at every decade (every second one beyond eight decades), unlabelled ticks at
    2 … 9 × 10^k while there are at most four decades."""
    first, last = round(np.log10(low)), round(np.log10(high))
    every = 1 if last - first <= 8 else 2
    splits, values = [], []
    for exponent in range(first, last + 1):
        splits.append(10.0**exponent)
        values.append(decade_label(exponent) if (exponent - last) % every == 0 else "")
        if last - first <= 4 and exponent < last:
            splits += [m * 10.0**exponent for m in range(2, 10)]
            values += [""] * 8
    return {"splits": splits, "values": values}


def append(buffer: np.ndarray, trace: np.ndarray, rows: int) -> np.ndarray:
    """The scope buffer after a frame's new samples ``trace``, at most ``rows`` long.  A trace that
    starts at or before the buffer's newest time is a new run (a Reset, or a slider move the
    exercise answers with a fresh simulation): the old window is dropped, not joined to it
    (issue 11, defect 6: a diagonal line back to t = 0 and a gap in the ±3σ band)."""
    if len(trace) and len(buffer) and trace[0, 0] <= buffer[-1, 0]:
        buffer = buffer[:0]
    return np.concatenate([buffer, trace])[-rows:]


class ScopeWindow:
    """The storage behind a tab's scope buffer: ``append`` gives the same rows as the function
    ``append`` (its obvious twin), without copying the whole window every frame.

    The rows live in a column-major backing array with spare rows after the newest: a frame
    writes its new samples into the spare rows and hands out a view of the newest ``rows``; only
    when the spare rows run out are the newest rows copied to a fresh backing array (on average
    ``1 / SPARE`` of a window per window of new samples, instead of a whole window per frame).
    The rows a view covers are never written again (a writer only fills rows beyond the newest
    handed out, and a fresh backing array leaves the old one untouched), so a reader may keep a
    view without the lock.  Column by column in memory, the scope's per-chart scans
    (``app.panels.scope_charts``) read one contiguous column instead of one value per row."""

    SPARE = 0.5                   # spare rows, as a share of the window

    def __init__(self) -> None:
        self.backing: np.ndarray | None = None
        self.end = 0                              # rows of ``backing`` written (and at most handed out)
        self.shown: np.ndarray | None = None      # the view handed out last

    def append(self, buffer: np.ndarray, trace: np.ndarray, rows: int) -> np.ndarray:
        """``append(buffer, trace, rows)``; in place when ``buffer`` is the view this window handed
        out last (any other buffer, e.g. emptied by a reset, starts a fresh backing array)."""
        if not len(trace):                        # nothing new: the newest rows, still this window's
            view = buffer[len(buffer) - min(len(buffer), rows):]
            if buffer is self.shown:
                self.shown = view
            return view
        if len(buffer) and trace[0, 0] <= buffer[-1, 0]:
            buffer = buffer[:0]                   # a new run (see ``append``)
        keep = min(len(buffer) + len(trace), rows)
        backing = self.backing
        if (buffer is not self.shown or backing is None or backing.shape[1] != trace.shape[1]
                or self.end + len(trace) > len(backing)):
            kept = buffer[len(buffer) - (keep - min(len(trace), keep)):]
            backing = np.empty((keep + max(int(self.SPARE * rows), len(trace)), trace.shape[1]),
                               dtype=np.result_type(buffer, trace), order="F")
            backing[:len(kept)] = kept
            self.backing, self.end = backing, len(kept)
        new = trace[len(trace) - min(len(trace), keep):]
        backing[self.end:self.end + len(new)] = new
        self.end += len(new)
        self.shown = backing[self.end - keep:self.end]
        return self.shown


def spanning(rows: np.ndarray, window_ms: float) -> tuple[np.ndarray, np.ndarray]:
    """The frame's rows and their time axis [ms before the newest sample], starting exactly at
    −window: while the window fills (after a start or reset) the oldest row is repeated there,
    so the x extent of the data never moves."""
    t_ms = (rows[:, 0] - rows[-1, 0]) * 1e3
    if t_ms[0] > -window_ms + 1e-9:
        rows, t_ms = np.vstack([rows[:1], rows]), np.concatenate([[-window_ms], t_ms])
    else:
        t_ms = t_ms.copy()
        t_ms[0] = -window_ms
    return rows, t_ms
