"""The Scope tab's rolling charts: what one frame sends from a tab's scope buffer.

Per frame and chart, the rows holding the min and max of the roughest series in
``SCOPE_BUCKETS`` buckets aligned to absolute sample numbers (<= 152 points, envelope
kept, no shimmer while scrolling), sent as float32 (float64 time axis once float32
cannot resolve a sample) straight to the wire, only when new samples arrived.
``chart_frame`` does in one compiled call what a dozen small numpy calls did per chart
and frame; ``scope_rows_reference`` is the slow, obvious twin it is tested against.
"""

from __future__ import annotations

import numba
import numpy as np
import viser

from app.infra.viser_internals import send_data
from app.panels import scope
from lab_modules.exercises import Chart

SCOPE_BUCKETS = 75                # per chart and frame: the extremes of the roughest series in this many
                                  # time buckets, i.e. <= 150 points across the ~500 px plot
ROUGHNESS_ROWS = 200              # newest rows that decide which series is the roughest
SCOPE_ASPECT = 2.2                # width / height of a scope chart
JIT = {"nogil": True, "cache": True}


#: The scope's time axes: the rolling window (time before the newest sample) or, to read when
#: something happened in a run, the time since Reset, one window-long page after the other
TIME_AXES = ("time before now", "time since reset")
SINCE_RESET = TIME_AXES[1]


def time_axis_choice(gui, initial: str):
    """The Scope tab's "Time axis" dropdown: the time before now (rolling) or the time since reset."""
    return gui.add_dropdown("Time axis", TIME_AXES, initial_value=initial,
                            hint="Time before the newest sample (rolling), or the time since Reset, one window "
                                 "after the other (to read when something happened in the run).")


class ScopeCharts:
    """The scope charts of one generation of an exercise, in the Scope tab."""

    def __init__(self, gui, charts: tuple[Chart, ...], columns: dict[str, int], window_ms: float,
                 time_axis: str = TIME_AXES[0]):
        self.charts = charts
        self.plans = [chart_plan(chart, columns) for chart in charts]
        self.y_ranges = [scope.StickyRange() for _ in charts]
        self.time_axis = time_axis
        self.handles = [self._add(gui, chart, window_ms, time_axis) for chart in charts]
        self.drawn_until: float | None = None     # time [s] of the newest sample drawn
        self.frames_drawn = 0

    @staticmethod
    def _add(gui, chart: Chart, window_ms: float, time_axis: str, order: float | None = None):
        x_label = "time since reset [s]" if time_axis == SINCE_RESET else "time before now [ms]"
        series = [viser.uplot.Series(label=x_label)]
        if chart.band:
            series += [viser.uplot.Series(label="+3σ", stroke="rgba(214,39,40,0.35)", width=1),
                       viser.uplot.Series(label="−3σ", stroke="rgba(214,39,40,0.35)", width=1)]
        series += [viser.uplot.Series(label=s.label, stroke=s.color, width=1.5) for s in chart.series]
        series += [scope.ANCHOR_SERIES, scope.LAYOUT_SERIES]   # y range held still; axes laid out each frame
        bands = (viser.uplot.Band(series=(1, 2), fill="rgba(214,39,40,0.12)"),) if chart.band else None
        extent = (0.0, window_ms * 1e-3) if time_axis == SINCE_RESET else (-window_ms, 0.0)
        return gui.add_uplot(
            scope.placeholder(*extent, len(series) - 1), tuple(series),
            title=f"{chart.title} [{chart.unit}]", bands=bands,
            **scope.chart_options(x_label, f"[{chart.unit}]"),
            scales={"x": viser.uplot.Scale(time=False)}, aspect=SCOPE_ASPECT, order=order)

    def set_time_axis(self, gui, time_axis: str, window_ms: float) -> None:
        """Make the charts anew on ``time_axis`` (the x label is part of a chart's options), in their
        places; call inside the Scope tab's container, holding the tab's GUI lock."""
        if time_axis == self.time_axis:
            return
        self.time_axis = time_axis
        for index, (chart, handle) in enumerate(zip(self.charts, self.handles)):
            order = handle.order
            handle.remove()
            self.handles[index] = self._add(gui, chart, window_ms, time_axis, order)
        self.y_ranges = [scope.StickyRange() for _ in self.charts]
        self.drawn_until = None                   # the next frame draws them

    def draw(self, buffer: np.ndarray, sample_time_s: float, window_ms: float, now: float,
             closed=lambda: False, fit: bool = False) -> bool:
        """Send the charts: only when new samples arrived (or to ``fit`` the y ranges to the
        traces at once, a stopped run's), as float32, and only the rows ``scope_rows`` picks (the
        chart's pixel width, not the buffer's length); call inside the frame's one atomic block.
        Whether it drew (or, fitting, found nothing to fit)."""
        if len(buffer) < 2:
            return fit
        if buffer[-1, 0] == self.drawn_until and not fit:
            return False
        self.drawn_until = buffer[-1, 0]
        if self.time_axis == SINCE_RESET:
            rows, frame_ms, page_start_s = page(buffer, window_ms)
            # the x axis is the time since reset [s]: float32 while that resolves a sample
            float32_time = float32_resolves(np.array((page_start_s + window_ms * 1e-3,)), sample_time_s)
        else:
            rows, frame_ms, page_start_s = buffer, window_ms, None
            # the time axis runs from -window to 0 ms: float32 while that resolves a sample
            float32_time = float32_resolves(np.array((window_ms,)), sample_time_s * 1e3)
        self.frames_drawn += 1
        for chart, plan, handle, y_range in zip(self.charts, self.plans, self.handles, self.y_ranges):
            if closed():
                return
            t_ms, t32, ys, low, high = chart_frame(rows, *plan, sample_time_s, frame_ms,
                                                   SCOPE_BUCKETS, ROUGHNESS_ROWS)
            band = 2 if chart.band else 0
            if band and not chart.band_in_range:  # the range follows the series; the band is cut at its edges
                low, high = finite_extremes(ys[band:])
            if fit:
                y_range.fit(low, high)
            else:
                y_range.follow(low, high, now)
            if band and not chart.band_in_range and y_range.shown() is not None:
                np.clip(ys[:band], *y_range.shown(), out=ys[:band])
            if page_start_s is not None:
                t_ms, ys = on_page(t_ms, ys, frame_ms, page_start_s, window_ms)
                t32 = t_ms.astype(np.float32)
            send_data(handle, (t32 if float32_time else t_ms, *ys, scope.anchor(y_range.shown()),
                               scope.layout(self.frames_drawn)))
        return True


def page(buffer: np.ndarray, window_ms: float) -> tuple[np.ndarray, float, float]:
    """The time-since-reset axis: the rows of the newest window-long page (pages start at whole
    multiples of the window after reset), the page's time so far [ms] and its start [s]."""
    window_s = window_ms * 1e-3
    last = buffer[-1, 0]
    start = np.floor(last / window_s + 1e-9) * window_s
    rows = buffer[np.searchsorted(buffer[:, 0], start - 1e-12):]
    return rows, max((last - start) * 1e3, 1e-9), float(start)


def on_page(t_ms: np.ndarray, ys: np.ndarray, frame_ms: float, page_start_s: float,
            window_ms: float) -> tuple[np.ndarray, np.ndarray]:
    """A frame's time axis [ms before its newest row] as time since reset [s] on its page, and one
    more point at the page's end with no values (NaN: uPlot draws nothing there), so the x extent
    is the whole page and holds still until the next page (see ``scope``: a moving extent
    confuses viser's chart)."""
    since_s = page_start_s + (t_ms + frame_ms) * 1e-3
    pad = np.full((ys.shape[0], 1), np.nan, dtype=ys.dtype)
    return np.append(since_s, page_start_s + window_ms * 1e-3), np.hstack([ys, pad])


def finite_extremes(ys: np.ndarray) -> tuple[float, float]:
    """The lowest and highest finite value of ``ys`` (inf, −inf if none)."""
    finite = ys[np.isfinite(ys)]
    return (float(finite.min()), float(finite.max())) if finite.size else (np.inf, -np.inf)


def chart_plan(chart: Chart, columns: dict[str, int]) -> tuple:
    """``frames.chart_frame``'s arguments describing ``chart``: its series' buffer columns (for
    the roughness and the values), their scales, the band's (centre, σ) columns or (-1, -1)."""
    series = np.array([columns[s.column] for s in chart.series], dtype=np.int64)
    band = np.array([columns[c] for c in chart.band] if chart.band else (-1, -1), dtype=np.int64)
    return (series, series, np.array([s.scale for s in chart.series], dtype=float), band,
            float(chart.series[0].scale))


def scope_rows_reference(buffer: np.ndarray, columns: list[int], sample_time_s: float,
                buckets: int = SCOPE_BUCKETS) -> np.ndarray:
    """Rows of the scope buffer to draw: the buffer's time span cut into ``buckets`` buckets
    of whole samples, and in each the rows of the lowest and the highest value of the
    roughest series among ``columns`` (largest mean step), plus the first and last rows.

    Drawn as lines, these points trace the same envelope as every sample (a noisy trace
    stays a band of the same height, a peak keeps its height), with at most ``2 buckets + 2``
    points.  The buckets are aligned to absolute sample numbers, so a sample once chosen
    stays chosen while the trace scrolls (no shimmer).

    The scope draws with the compiled ``scope_rows``; this is its slow, obvious twin."""
    n = len(buffer)
    size = -(-n // buckets)
    if size <= 2:
        return np.arange(n)
    key = buffer[:, 0]
    if len(columns) == 1:
        if np.isfinite(buffer[:, columns[0]]).all():
            key = buffer[:, columns[0]]
    else:
        recent = buffer[-ROUGHNESS_ROWS:, columns]
        finite = np.isfinite(recent).all(axis=0)
        if finite.any():
            roughness = np.where(finite, np.abs(np.diff(recent, axis=0)).sum(axis=0), -1.0)
            choice = buffer[:, columns[int(np.argmax(roughness))]]
            if np.isfinite(choice).all():
                key = choice
    first = round(buffer[0, 0] / sample_time_s)
    lead = first % size
    padded = np.empty(lead + n + (-(lead + n)) % size)
    padded[:lead], padded[lead:lead + n], padded[lead + n:] = key[0], key, key[-1]   # the edge rows' values
    padded = padded.reshape(-1, size)
    base = np.arange(len(padded)) * size - lead
    low, high = base + padded.argmin(axis=1), base + padded.argmax(axis=1)
    rows = np.empty(2 * len(base) + 2, dtype=np.intp)
    rows[0], rows[-1] = 0, n - 1
    rows[1:-1:2], rows[2:-1:2] = np.minimum(low, high), np.maximum(low, high)   # in time order
    np.clip(rows, 0, n - 1, out=rows)
    keep = np.empty(len(rows), dtype=bool)
    keep[0], keep[1:] = True, rows[1:] != rows[:-1]
    return rows[keep]


def float32_resolves(t_ms: np.ndarray, step_ms: float) -> bool:
    """Whether float32 keeps times ``step_ms`` apart distinct (long runs need float64)."""
    return bool(np.spacing(np.float32(np.abs(t_ms).max())) <= step_ms / 16)


@numba.njit(**JIT)
def scope_rows(buffer, columns, sample_time_s, buckets, roughness_rows):
    """``scope_rows_reference`` compiled (the same rows; see its docstring)."""
    n = buffer.shape[0]
    size = -(-n // buckets)
    if size <= 2:
        return np.arange(n)
    key_column = 0
    if len(columns) == 1:
        if np.isfinite(buffer[:, columns[0]]).all():
            key_column = columns[0]
    else:
        start = max(n - roughness_rows, 0)
        best, best_value, any_finite = 0, -1.0, False
        for j in range(len(columns)):
            column = columns[j]
            finite, total = True, 0.0
            for r in range(start, n):
                if not np.isfinite(buffer[r, column]):
                    finite = False
                    break
            if finite:
                any_finite = True
                for r in range(start + 1, n):
                    total += abs(buffer[r, column] - buffer[r - 1, column])
            else:
                total = -1.0
            if j == 0 or total > best_value:
                best, best_value = j, total
        if any_finite and np.isfinite(buffer[:, columns[best]]).all():
            key_column = columns[best]
    first = np.int64(np.rint(buffer[0, 0] / sample_time_s))
    lead = first % size
    count = (lead + n + size - 1) // size
    rows = np.empty(2 * count + 2, dtype=np.intp)
    rows[0] = 0
    for b in range(count):
        # the padding repeats the edge rows' values, and the first of equal values wins: the padded
        # positions never win over the edge rows themselves, so only the rows in the bucket are read
        start = max(b * size - lead, 0)
        low_row, high_row = start, start
        low_value = high_value = buffer[start, key_column]
        for r in range(start + 1, min((b + 1) * size - lead, n)):
            value = buffer[r, key_column]
            if value < low_value:
                low_row, low_value = r, value
            if value > high_value:
                high_row, high_value = r, value
        rows[1 + 2 * b] = min(low_row, high_row)
        rows[2 + 2 * b] = max(low_row, high_row)
    rows[-1] = n - 1
    kept = 1
    for i in range(1, len(rows)):
        if rows[i] != rows[kept - 1]:
            rows[kept] = rows[i]
            kept += 1
    return rows[:kept]


@numba.njit(**JIT)
def chart_frame(buffer, key_columns, value_columns, scales, band_columns, band_scale,
                sample_time_s, window_ms, buckets, roughness_rows):
    """One chart's frame from the scope buffer: (time axis [ms before the newest sample]
    starting at −``window_ms``, the same as float32, float32 rows (+3σ, −3σ if ``band_columns`` = (centre, σ)
    is not (-1, -1), then every series × its scale), lowest and highest finite value drawn
    (inf, −inf if none))."""
    rows = scope_rows(buffer, key_columns, sample_time_s, buckets, roughness_rows)
    last_time = buffer[rows[-1], 0]
    pad = 1 if (buffer[rows[0], 0] - last_time) * 1e3 > -window_ms + 1e-9 else 0
    m = len(rows) + pad
    band = 2 if band_columns[0] >= 0 else 0
    ys = np.empty((band + len(value_columns), m), dtype=np.float32)
    t_ms = np.empty(m)
    low, high = np.inf, -np.inf
    for i in range(m):
        r = rows[max(i - pad, 0)]
        t_ms[i] = (buffer[r, 0] - last_time) * 1e3
        for j in range(band + len(value_columns)):
            if j < band:
                centre, sigma = buffer[r, band_columns[0]], buffer[r, band_columns[1]]
                value = (centre + 3 * sigma if j == 0 else centre - 3 * sigma) * band_scale
            else:
                value = buffer[r, value_columns[j - band]] * scales[j - band]
            ys[j, i] = value
            if np.isfinite(value):
                low, high = min(low, value), max(high, value)
    t_ms[0] = -window_ms
    return t_ms, t_ms.astype(np.float32), ys, low, high
