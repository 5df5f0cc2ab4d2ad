"""The debugger's branch in time: the overlay chart (original solid, branch dashed, the shown
sample as a vertical line) and keeping a branch through the exercise's own controls."""

import numpy as np
import pytest

from app.panels.filter_branch import SERIES, kept_values, overlay_chart
from lab_modules.estimators.filter_history import branch
from lab_modules.exercises import get


def history_of(name: str, samples: int = 1000):
    exercise = get(name)
    values = exercise.resolve({})
    simulation = exercise.simulation(values)
    simulation.advance(samples)
    return exercise, values, simulation.filter_tape().history()


def test_overlay_draws_the_branch_dashed_over_its_horizon_and_marks_the_shown_sample():
    _, _, history = history_of("ekf_disturbance")
    rerun = branch(history, 500, history.model.scaled(q_scale=10.0), horizon=300)
    data, _ = overlay_chart(history, 520, 0, rerun, after=300)
    assert len(data) == len(SERIES)
    t_ms, original, *_, branch_x, _, _, mark = data
    labels = [series["label"] for series in SERIES]
    assert labels[1] == "x̂⁺" and labels[5] == "branch x̂⁺" and labels[8] == "shown sample"
    assert SERIES[5].get("dash") and not SERIES[1].get("dash")
    shown = np.flatnonzero(np.abs(t_ms) < 1e-6)
    assert len(shown) == 2 and np.all(np.isfinite(mark[shown])) and np.sum(np.isfinite(mark)) == 2
    assert mark[shown[0]] < mark[shown[1]]                                       # a vertical line
    branch_times = t_ms[np.isfinite(branch_x)]
    step_ms = history.model.sample_time_s * 1e3
    assert branch_times[0] == pytest.approx(-20 * step_ms) and branch_times[-1] == pytest.approx(279 * step_ms)
    assert not np.allclose(branch_x[np.isfinite(branch_x)], original[np.isfinite(branch_x)])
    none = overlay_chart(history, 520, 0, None)[0]                               # dropped: no dashed lines
    assert all(np.all(np.isnan(series)) for series in none[5:8])


def test_keeping_a_branch_sets_the_controls_that_give_exactly_its_q_and_r():
    exercise, values, history = history_of("kalman_noise")
    changed = kept_values(exercise, values, history.model, 10.0, 0.5)
    assert changed["filter_r_position"] == pytest.approx(0.5 * values["filter_r_position"])
    assert changed["filter_q_current"] == pytest.approx(10.0 * values["filter_q_current"])
    kept = exercise.simulation({**values, **changed}).filter_tape().model
    np.testing.assert_allclose(kept.Q, 10.0 * history.model.Q, rtol=1e-12)
    np.testing.assert_allclose(kept.R, 0.5 * history.model.R, rtol=1e-12)


@pytest.mark.parametrize("name", ["maglev_tracking", "adaptive_filter"])
def test_a_branch_the_controls_cannot_express_is_not_kept(name):
    exercise, values, history = history_of(name, 200)
    assert kept_values(exercise, values, history.model, 10.0, 1.0).startswith("Not kept")


@pytest.mark.parametrize("name, pair, kind", [("maglev_tracking", (0, 1), "vertical"),
                                              ("adaptive_filter", (0, 3), "sloped"),
                                              ("adaptive_filter", (0, 1), "none"),
                                              ("kalman_noise", (0, 1), "none")])
def test_ellipse_chart_draws_a_scalar_measurements_constraint_line(name, pair, kind):
    from app.panels.filter_debugger import ellipse_chart, ellipse_series
    _, _, history = history_of(name, 600)
    data, _ = ellipse_chart(history, 300, pair)
    assert len(data) == len(ellipse_series())
    x, line = data[0], data[-1]
    drawn = np.isfinite(line)
    if kind == "vertical":                               # H = [1 0 0]: the gap x₁ = y, whatever x₂
        assert drawn.sum() == 2 and x[drawn][0] == x[drawn][1]
        assert x[drawn][0] == pytest.approx(history.y[300, 0] * 1e6)          # in µm
    elif kind == "sloped":                               # H picks x_M: a level line at y
        assert drawn.sum() > 10 and np.ptp(line[drawn]) == pytest.approx(0.0, abs=1e-12)
    else:
        assert not drawn.any()
    ellipses = np.concatenate(data[1:13])
    assert np.isfinite(ellipses).sum() > 100                                    # the ellipses have points
