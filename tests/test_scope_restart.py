"""The scope never joins an old run to a new one (issue 11, defect 6): after a Reset, or a
slider move that an exercise answers with a fresh simulation, the buffer holds the new run only
and its time axis rises monotonically, in every exercise."""

from __future__ import annotations

import numpy as np
import pytest

from app.panels import scope
from tests.example_exercise import contract_exercises

EXERCISES = contract_exercises()


def _moved(exercise, values: dict) -> dict:
    """The values with the first continuous parameter (not the time scale) moved a little."""
    ranges = exercise.parameter_ranges(values)
    for p in exercise.parameters:
        low, high = ranges.get(p.name, (p.minimum, p.maximum))
        if not p.choices and not p.integer and p.name != "time_scale" and high > low:
            value = values[p.name] + 0.01 * (high - low)
            return {**values, p.name: value if value <= high else values[p.name] - 0.01 * (high - low)}
    raise AssertionError(f"{exercise.name} has no continuous parameter")


def test_append_drops_the_old_window_when_time_restarts():
    old = np.column_stack([np.arange(10, 20) * 1e-3, np.ones(10)])
    carried = np.column_stack([np.arange(20, 25) * 1e-3, np.ones(5)])
    restarted = np.column_stack([np.arange(0, 5) * 1e-3, np.zeros(5)])
    assert np.array_equal(scope.append(old, carried, 100)[:, 0], np.arange(10, 25) * 1e-3)
    assert np.array_equal(scope.append(old, restarted, 100), restarted)
    assert len(scope.append(old, carried, 8)) == 8


@pytest.mark.parametrize("name", list(EXERCISES))
def test_scope_buffer_after_a_slider_move_and_a_reset(name):
    exercise = EXERCISES[name]
    values = exercise.resolve({})
    first = exercise.simulation(values)
    steps = max(round(0.005 / first.sample_time_s), 20)
    buffer = scope.append(np.empty((0, 1 + len(first.columns))), first.advance(steps), 10**6)
    for following in (exercise.retune(first, _moved(exercise, values)), exercise.simulation(values)):
        before = buffer[-1, 0]
        trace = following.advance(steps)
        buffer = scope.append(buffer, trace, 10**6)
        assert np.all(np.diff(buffer[:, 0]) > 0), name
        if trace[0, 0] <= before:                     # a new run: the buffer holds it alone
            assert np.array_equal(buffer, trace, equal_nan=True)


def test_the_scope_window_holds_the_rows_of_append_and_never_changes_a_view_it_handed_out():
    """``scope.ScopeWindow`` against its twin ``scope.append``: frames of varied length, a window
    that shrinks and grows (the time scale), new runs, an empty frame and a buffer emptied from
    outside (a reset); every view handed out keeps its rows while later frames are written."""
    rng = np.random.default_rng(3)
    window = scope.ScopeWindow()
    shown = expected = np.empty((0, 3))
    handed_out, backings = [], set()
    t = 0
    for frame in range(400):
        rows = 50 if frame < 150 else (20 if frame < 250 else 90)
        n = int(rng.integers(0, 12))
        if frame % 97 == 96:
            t = 0                                     # a new run starts at time 0
        trace = np.column_stack([np.arange(t, t + n) * 1e-3, rng.standard_normal((n, 2))])
        t += n
        if frame % 131 == 130:
            shown = expected = shown[:0]              # emptied from outside
        shown = window.append(shown, trace, rows)
        expected = scope.append(expected, trace, rows)
        assert np.array_equal(shown, expected), frame
        handed_out.append((shown, shown.copy()))
        backings.add(id(window.backing))
    assert all(np.array_equal(view, rows) for view, rows in handed_out)
    assert len(backings) < 100, "most frames are written in place, not copied with their window"
