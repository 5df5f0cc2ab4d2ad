"""The debugger's branch in time: the overlay chart (original solid, branch dashed, the shown
sample as a vertical line) and keeping a branch through the exercise's own controls."""

import numpy as np
import pytest

from app.panels.filter_branch import kept_values, overlay_chart
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
    data, options = overlay_chart(history, 520, 0, rerun, after=300)
    t_ms, original, *_, branch_x, _, _, mark = data
    labels = [series["label"] for series in options["series"]]
    assert labels[1] == "x̂⁺" and labels[5] == "branch x̂⁺" and labels[8] == "shown sample"
    assert options["series"][5].get("dash") and not options["series"][1].get("dash")
    shown = np.flatnonzero(t_ms == 0.0)
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
