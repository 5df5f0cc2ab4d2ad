"""What the scope sends per frame: the rows ``_scope_rows`` picks keep the trace's envelope,
fit the pixel budget and stay put while the trace scrolls; float32 only while it resolves a sample."""

from __future__ import annotations

import numpy as np

from app.panels.scope_charts import SCOPE_BUCKETS
from app.panels.scope_charts import float32_resolves as _float32_resolves
from app.panels.scope_charts import scope_rows_reference as _scope_rows

T = 50e-6


def _buffer(first_sample: int, n: int = 1000, seed: int = 0) -> np.ndarray:
    k = np.arange(first_sample, first_sample + n)
    rng = np.random.default_rng(seed)
    noise = rng.normal(size=k.max() + 1)[k]           # the same sample number has the same value
    return np.column_stack([k * T, noise, np.sin(k / 80.0), np.full(n, np.nan)])


def test_rows_keep_the_envelope_within_the_budget():
    buffer = _buffer(12_345)
    rows = _scope_rows(buffer, [1, 2], T)
    assert len(rows) <= 2 * SCOPE_BUCKETS + 2 < len(buffer) / 4
    assert np.all(np.diff(rows) > 0) and rows[0] == 0 and rows[-1] == len(buffer) - 1
    assert buffer[rows, 1].max() == buffer[:, 1].max() and buffer[rows, 1].min() == buffer[:, 1].min()
    # in every bucket of the noisy series, its extremes are drawn
    size = -(-len(buffer) // SCOPE_BUCKETS)
    lead = 12_345 % size
    for start in range(-lead, len(buffer), size):
        part = slice(max(start, 0), start + size)
        chosen = rows[(rows >= max(start, 0)) & (rows < start + size)]
        assert buffer[chosen, 1].max() == buffer[part, 1].max()


def test_rows_stay_put_while_the_trace_scrolls():
    before, after = _buffer(20_000), _buffer(20_008)  # eight new samples, as in one frame
    drawn_before = set(before[_scope_rows(before, [1, 2], T), 0])
    drawn_after = set(after[_scope_rows(after, [1, 2], T), 0])
    overlap = drawn_before & drawn_after
    assert len(overlap) >= 0.9 * len(drawn_after)


def test_non_finite_series_and_short_buffers():
    buffer = _buffer(0, n=100)
    assert np.array_equal(_scope_rows(buffer[:2], [1], T), [0, 1])
    rows = _scope_rows(buffer, [3], T)                # all NaN: buckets by time, still a valid subset
    assert len(rows) <= len(buffer) and np.all(np.diff(rows) > 0)


def test_float32_time_axis_only_while_it_resolves_a_sample():
    assert _float32_resolves(np.array([1e3, 2e3]), T * 1e3)
    assert not _float32_resolves(np.array([1e6, 1e6 + 1]), T * 1e3)
