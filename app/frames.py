"""Every tab's scope frames: a few shared threads per process on the 25 Hz clock, and a
compiled kernel that turns a tab's scope buffer into one chart's frame.

One thread per tab woke 25 times a second per tab and handed the GIL around between
dozens of threads; here each process has ``FRAME_THREADS`` frame threads, and every
tab is one ``Ticker`` on one of them (the one with the fewest).  A thread calls its
tickers one after the other on an absolute clock; when a round takes longer than a
frame, the next round starts at once and every tab's rate drops alike (the simulation
still follows real time: each tab advances by the time since its own last frame).

``chart_frame`` does in one compiled call what a dozen small numpy calls did per chart
and frame (``session._scope_rows`` is the reference it is tested against): pick the
rows that keep the envelope, the time axis [ms before now], the scaled series and
±3σ band as float32, and the finite range of what is drawn.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numba
import numpy as np

FRAME_S = 1 / 25                  # display refresh
FRAME_THREADS = 2                 # frame threads per process (the numba loops release the GIL, so
                                  # two threads use two cores in a single process; more only add hand-offs)
JIT = {"nogil": True, "cache": True}


class Ticker:
    """One tab's place on the frame clock: ``step(now)`` is called every frame until it
    returns False (the tab closed or switched).  Quacks like the thread it replaces."""

    def __init__(self, step: Callable[[float], bool], name: str):
        self.step, self.name = step, name
        self.finished = threading.Event()

    def is_alive(self) -> bool:
        return not self.finished.is_set()

    def join(self, timeout: float | None = None) -> None:
        self.finished.wait(timeout)


class _FrameThread:
    def __init__(self, index: int, period_s: float):
        self.period_s = period_s
        self.tickers: list[Ticker] = []
        self.wakeup = threading.Condition()
        self.thread = threading.Thread(target=self._loop, name=f"frames-{index}", daemon=True)
        self.thread.start()

    def add(self, ticker: Ticker) -> None:
        with self.wakeup:
            self.tickers.append(ticker)
            self.wakeup.notify()

    def _loop(self) -> None:
        next_frame = time.perf_counter()
        while True:
            with self.wakeup:
                while not self.tickers:
                    self.wakeup.wait()
                    next_frame = time.perf_counter()
                tickers = tuple(self.tickers)
            next_frame += self.period_s               # a steady rate: the frame's own work is not added
            delay = next_frame - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            else:
                next_frame = time.perf_counter()      # behind (a busy server): no burst of frames to catch up
            finished = []
            for ticker in tickers:
                try:
                    keep = ticker.step(time.perf_counter())
                except Exception:  # noqa: BLE001 - a step reports its own errors; never stop the others
                    keep = True
                if not keep:
                    finished.append(ticker)
            if finished:
                with self.wakeup:
                    self.tickers = [t for t in self.tickers if t not in finished]
                for ticker in finished:
                    ticker.finished.set()


class FrameClock:
    """The process's frame threads (all started on first use)."""

    def __init__(self, threads: int = FRAME_THREADS, period_s: float = FRAME_S):
        self.count, self.period_s = threads, period_s
        self.threads: list[_FrameThread] = []
        self.lock = threading.Lock()

    def add(self, step: Callable[[float], bool], name: str = "tab") -> Ticker:
        """Call ``step(now)`` every frame until it returns False; on the least busy thread."""
        ticker = Ticker(step, name)
        with self.lock:
            if not self.threads:                      # all at once: the thread count stays put from here on
                self.threads = [_FrameThread(index, self.period_s) for index in range(self.count)]
            thread = min(self.threads, key=lambda t: len(t.tickers))
        thread.add(ticker)
        return ticker

    def tabs(self) -> int:
        return sum(len(t.tickers) for t in self.threads)


CLOCK = FrameClock()


# -- the compiled frame kernel ----------------------------------------------------------

@numba.njit(**JIT)
def scope_rows(buffer, columns, sample_time_s, buckets, roughness_rows):
    """``session._scope_rows`` compiled (the same rows; see its docstring)."""
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
        low_row, high_row = -1, -1
        low_value, high_value = 0.0, 0.0
        for p in range(b * size - lead, (b + 1) * size - lead):
            r = min(max(p, 0), n - 1)                 # the padding repeats the edge rows' values
            value = buffer[r, key_column]
            if low_row < 0 or value < low_value:
                low_row, low_value = p, value
            if high_row < 0 or value > high_value:
                high_row, high_value = p, value
        rows[1 + 2 * b] = min(max(min(low_row, high_row), 0), n - 1)
        rows[2 + 2 * b] = min(max(max(low_row, high_row), 0), n - 1)
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
