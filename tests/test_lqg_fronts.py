"""The PID front of ``lqg_vs_pid`` assembles its loops from matrices (``analysis.closed_loop_matrices``):
every design's figures equal, to the last bit, those of the same design built through python-control."""

import numpy as np
import pytest

from lab_modules.controllers.pid import pid
from lab_modules.exercises import _lqg_vs_pid_fronts as fronts
from lab_modules.exercises import lqg_vs_pid
from lab_modules.exercises._lqg_vs_pid_design import SET_UP_CONTROLS, derivative_filter_ratio
from lab_modules.loops.radial_axis_step_tests import loop_figures
from lab_modules.parameters import in_si


@pytest.mark.parametrize("pid_feedback", ["estimated", "measured"])
def test_pid_front_equals_designs_built_through_python_control(pid_feedback):
    values = {**lqg_vs_pid.EXERCISE.resolve({}), "pid_feedback": pid_feedback}
    designs = fronts.pid_front(values)
    _, common = fronts.linear_common(fronts.PID_FRONT_SETTINGS,
                                      tuple(values[name] for name in fronts.PID_FRONT_SETTINGS))
    integral_time_s = in_si(SET_UP_CONTROLS, values)["integral_time_ms"]
    n_factors = len(fronts.FRONT_PID_GAIN_FACTORS)
    for i, derivative_time_s in enumerate(fronts.FRONT_PID_DERIVATIVE_TIMES_S[::3]):
        controller = pid(values["pid_gain"], integral_time_s, derivative_time_s,
                         derivative_filter_ratio(values) * derivative_time_s, fronts.T)
        for j in (0, n_factors // 2, n_factors - 1):
            axis = common.with_changes(controller=fronts.FRONT_PID_GAIN_FACTORS[j] * controller,
                                       use_estimate=pid_feedback == "estimated")
            row = loop_figures(axis)
            k = 3 * i * n_factors + j
            assert np.array_equal(designs.step_stiffness_n_per_m[k], row["step_stiffness_n_per_m"], equal_nan=True)
            assert np.array_equal(designs.min_dynamic_stiffness_n_per_m[k], row["min_dynamic_stiffness_n_per_m"],
                                  equal_nan=True)
            assert designs.noise_rms_current_a[k] == row["noise_rms_current_a"]
            assert np.array_equal(designs.peak_current_a_per_m[k], row["peak_current_a_per_m"], equal_nan=True)
            assert designs.min_damping[k] == row["min_damping"]


def test_pid_front_after_a_filter_move_reuses_the_sweeps_controllers(monkeypatch):
    """Only the PID's sliders change the sweep's seven controllers: after a move of the filter's
    weight the front is recomputed (other figures) without discretising a PID again."""
    values = lqg_vs_pid.EXERCISE.resolve({})
    before = fronts.pid_front(values)
    moved = {**values, "filter_q_velocity": values["filter_q_velocity"] * 1.5}

    def no_c2d(*_):
        raise AssertionError("a PID discretised again")
    monkeypatch.setattr(fronts, "pid", no_c2d)
    after = fronts.pid_front(moved)
    assert not np.array_equal(before.noise_rms_current_a, after.noise_rms_current_a, equal_nan=True)
