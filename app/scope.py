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

SHRINK_AFTER_S = 3.0          # a range three times too large for this long shrinks
#: For its first frames a scope shows a range this much wider than the traces need, then the
#: range itself.  uPlot lays out a chart's axes when a scale changes; a chart whose scale was set
#: before its panel had a size (right after a tab opened or an exercise switch) kept blank axes, no
#: tick labels at all, for as long as its range held still, and a later resize did not help (seen on
#: kalman_noise's and ekf_parameters' current charts; issue 11, defect 13).  The one planned change
#: of range lays the axes out again once the chart has its size.
SETTLE_FRAMES = 50
SETTLE_WIDEN = 1.5
HEADROOM = 1.2                # the range covers the traces with this factor
PADDING = (12, 16, 0, 4)      # top, right, bottom, left [px]: the top tick label stays inside the chart
Y_AXIS_SIZE = 56              # px for the y tick labels (five significant characters)


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

    def __init__(self, settle_frames: int = SETTLE_FRAMES) -> None:
        self.range: tuple[float, float] | None = None
        self.loose_since: float | None = None
        self.frames = 0
        self.settle_frames = settle_frames

    def shown(self) -> tuple[float, float] | None:
        """The range the anchor spans this frame: ``range``, widened for the first ``settle_frames``."""
        if self.range is None or self.frames >= self.settle_frames:
            return self.range
        low, high = self.range
        if low < 0 < high:
            return (low * SETTLE_WIDEN, high * SETTLE_WIDEN)
        return (low - (SETTLE_WIDEN - 1) * (high - low), high)

    def update(self, columns: list[np.ndarray], now: float | None = None) -> bool:
        """Follow the traces; True if the range changed."""
        finite = np.concatenate([c[np.isfinite(c)] for c in columns]) if columns else np.zeros(0)
        if finite.size == 0:
            return self.follow(math.inf, -math.inf, now)
        return self.follow(float(finite.min()), float(finite.max()), now)

    def follow(self, low: float, high: float, now: float | None = None) -> bool:
        """``update`` from the lowest and highest finite value drawn (nothing finite: low > high);
        called once per frame."""
        self.frames += 1
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
#: A style element for the page (``gui.add_html``): the anchor series stays out of the legends.
LEGEND_STYLE = f"<style>.u-legend .{ANCHOR_CLASS} {{ display: none; }}</style>"


def anchor(y_range: tuple[float, float] | None, n: int) -> np.ndarray:
    """The anchor series' values: alternately the range's ends (zeros before the first range)."""
    low, high = y_range if y_range is not None else (0.0, 0.0)
    return np.where(np.arange(n) % 2 == 1, high, low)


def chart_options(x_label: str, y_label: str) -> dict:
    """Axes, legend and padding shared by every chart of the lab: static legend (no '--'
    placeholders before a hover), room for the top tick label and for five-character y ticks."""
    return {"axes": (viser.uplot.Axis(label=x_label),
                     viser.uplot.Axis(label=y_label, size=Y_AXIS_SIZE)),
            "legend": viser.uplot.Legend(live=False),
            "padding": PADDING}


def append(buffer: np.ndarray, trace: np.ndarray, rows: int) -> np.ndarray:
    """The scope buffer after a frame's new samples ``trace``, at most ``rows`` long.  A trace that
    starts at or before the buffer's newest time is a new run (a Reset, or a slider move the
    exercise answers with a fresh simulation): the old window is dropped, not joined to it
    (issue 11, defect 6: a diagonal line back to t = 0 and a gap in the ±3σ band)."""
    if len(trace) and len(buffer) and trace[0, 0] <= buffer[-1, 0]:
        buffer = buffer[:0]
    return np.concatenate([buffer, trace])[-rows:]


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
