"""The compiled scope frame against its numpy reference, and the shared frame clock."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from app.panels import scope, scope_charts
from app.panels.scope_charts import ROUGHNESS_ROWS, SCOPE_BUCKETS
from app.panels.scope_charts import scope_rows_reference as _scope_rows
from app.tab import frames

T = 50e-6


def _buffer(first_sample: int, n: int = 1000, seed: int = 0) -> np.ndarray:
    k = np.arange(first_sample, first_sample + n)
    rng = np.random.default_rng(seed)
    return np.column_stack([k * T, rng.normal(size=n), np.sin(k / 80.0), np.abs(rng.normal(size=n)) * 0.1,
                            np.full(n, np.nan)])


@pytest.mark.parametrize("first, n, columns", [(12_345, 1000, [1, 2]), (20_008, 1000, [2, 1]), (0, 100, [4]),
                                               (7, 2, [1]), (3, 151, [1]), (99, 1000, [4, 2]), (5, 1000, [2])])
def test_compiled_rows_are_the_reference_rows(first, n, columns):
    buffer = _buffer(first, n)
    expected = _scope_rows(buffer, columns, T)
    got = scope_charts.scope_rows(buffer, np.array(columns, dtype=np.int64), T, SCOPE_BUCKETS, ROUGHNESS_ROWS)
    assert np.array_equal(got, expected)


def test_compiled_rows_on_the_scope_window_are_the_reference_rows():
    """The tab's buffer is a view of ``scope.ScopeWindow``'s column-major array, frame after frame,
    while the window fills and once it is full (each bucket size and alignment in turn), with
    equal values (a flat stretch) where the first of them must win."""
    source = _buffer(3_217, 6_000, seed=4)
    source[2_000:2_400, 1] = 0.5
    window = scope.ScopeWindow()
    buffer = np.empty((0, source.shape[1]))
    for start in range(0, len(source), 97):
        buffer = window.append(buffer, source[start:start + 97], 1_500)
        assert not buffer.flags.c_contiguous
        for columns in ([1], [2, 1], [4, 2]):
            expected = _scope_rows(np.ascontiguousarray(buffer), columns, T)
            got = scope_charts.scope_rows(buffer, np.array(columns, dtype=np.int64), T, SCOPE_BUCKETS, ROUGHNESS_ROWS)
            assert np.array_equal(got, expected), (start, columns)


@pytest.mark.parametrize("first, window_ms", [(40_000, 50.0), (40_000, 60.0)])   # full window, window filling
def test_compiled_chart_frame_is_the_reference_frame(first, window_ms):
    buffer = _buffer(first)
    columns, scales = [1, 2], [1e6, 2.0]
    rows, t_ms = scope.spanning(buffer[_scope_rows(buffer, columns, T)], window_ms)
    centre, sigma = rows[:, 1], rows[:, 3]
    expected = [(centre + 3 * sigma) * 1e6, (centre - 3 * sigma) * 1e6] + [rows[:, c] * s for c, s in
                                                                           zip(columns, scales)]
    got_t, t32, ys, low, high = scope_charts.chart_frame(buffer, np.array(columns), np.array(columns), np.array(scales),
                                              np.array([1, 3]), 1e6, T, window_ms, SCOPE_BUCKETS, ROUGHNESS_ROWS)
    assert np.array_equal(got_t, t_ms) and got_t[0] == -window_ms and np.array_equal(t32, t_ms.astype(np.float32))
    assert ys.dtype == np.float32 and ys.shape == (4, len(t_ms))      # band, series
    for row, want in zip(ys, expected):
        assert np.array_equal(row, want.astype(np.float32))
    assert (low, high) == (min(e.min() for e in expected), max(e.max() for e in expected))


def test_chart_frame_without_band_or_finite_values():
    buffer = _buffer(0, 300)
    t_ms, _, ys, low, high = scope_charts.chart_frame(buffer, np.array([4]), np.array([4]), np.array([1.0]),
                                             np.array([-1, -1]), 1.0, T, 15.0, SCOPE_BUCKETS, ROUGHNESS_ROWS)
    assert ys.shape == (1, len(t_ms)) and np.isnan(ys[0]).all() and low > high


def test_clock_steps_each_ticker_at_the_frame_rate_until_it_finishes():
    clock = frames.FrameClock(threads=2, period_s=0.02)
    calls = {"a": 0, "b": 0}

    def stepper(name, stop_after):
        def step(now):
            calls[name] += 1
            if calls[name] == 3 and name == "a":
                raise RuntimeError("a frame fails: the ticker goes on")
            return calls[name] < stop_after
        return step

    a, b = clock.add(stepper("a", 40)), clock.add(stepper("b", 5))
    assert {t.thread.name for t in clock.threads} == {"frames-0", "frames-1"}   # one ticker each
    b.join(timeout=2.0)
    assert not b.is_alive() and calls["b"] == 5
    time.sleep(0.5)
    assert a.is_alive() and 5 <= calls["a"] <= 35           # ~25 at 50 Hz over 0.6 s, never a burst
    assert clock.tabs() == 1 and threading.active_count() >= 3
    a.join(timeout=2.0)
    assert not a.is_alive() and calls["a"] == 40 and clock.tabs() == 0
