"""Issue 11's model-side defects, headless: what a worksheet task or a readout promises holds."""

from __future__ import annotations

import numpy as np
import pytest

from lab_modules.exercises import get
from lab_modules.parameters import ParameterError


# -- defect 11: maglev_tuning's still segment follows the recording --------------------------------
def test_still_segment_range_follows_the_recording():
    from lab_modules.exercises.maglev_tuning import recording
    exercise = get("maglev_tuning")
    values = exercise.resolve({})
    ranges = exercise.parameter_ranges(values)
    rec = recording(values)
    step = np.median(np.diff(rec.time_s))
    assert ranges["still_start_s"] == ranges["still_end_s"] == pytest.approx((rec.time_s[0], rec.time_s[-1] + step))
    assert ranges["still_end_s"][1] < 10.0 < exercise.parameters[0].maximum      # 6 s, not 3600 s
    with pytest.raises(ParameterError, match=r"inside the recording's 0 \.\.\. 6 s") as error:
        exercise.analyse(exercise.resolve({"still_start_s": 36.0, "still_end_s": 40.0}))
    assert "\n" not in str(error.value)


# -- defect 4: maglev_tracking task 1 (η3 = −200) ---------------------------------------------------
def _maglev_run(overrides: dict, seed: int, duration_s: float = 1.5):
    from lab_modules.exercises.maglev_tracking import setup
    from lab_modules.loops.maglev_loop import MaglevSimulation
    exercise = get("maglev_tracking")
    simulation = MaglevSimulation(setup(exercise.resolve({**overrides, "seed": seed})), seed=seed)
    trace = simulation.run(duration_s)
    return simulation, trace


def test_maglev_task_1_holds_the_ball_at_its_stated_noise_and_explains_a_strike_at_the_default():
    from pathlib import Path
    sheet = (Path(__file__).resolve().parents[1] / "static" / "worksheets" / "maglev_tracking.md").read_text()
    task = next(line for line in sheet.splitlines() if line.startswith("1. **Gain.**"))
    assert "σ to 0.1 mm" in task and "η₃ to −200" in task and "strikes the magnet" in task
    for seed in range(10):                           # the task's settings: the ball stays up on every seed
        simulation, trace = _maglev_run({"pole_3_rad_s": -200.0, "sensor_noise_mm": 0.1}, seed)
        assert simulation.status_message() == "", seed
        assert np.abs(trace["coil_voltage_v"][trace["time_s"] > 0.3]).max() < 200.0
    struck = [seed for seed in range(10) if _maglev_run({"pole_3_rad_s": -200.0}, seed, 0.3)[0].status_message()]
    assert struck                                    # at σ = 1 mm some seeds strike (0, 3, 5 of 0-9) ...
    message = _maglev_run({"pole_3_rad_s": -200.0}, struck[0], 0.3)[0].status_message()
    assert "struck the magnet" in message and "guarded" in message and "x̂3" in message   # ... and say why


# -- defect 8: sensor_placement task 4 shows the mode instability, not the step's current kick --------
def _placement_stop(gain_factor: float, step_um: float, n_steps: int = 8000) -> str:
    exercise = get("sensor_placement")
    simulation = exercise.simulation(exercise.resolve({"sensor_offset_mm": 0.0, "gain_factor": gain_factor,
                                                       "reference_step_um": step_um}))
    simulation.advance(n_steps)                      # 0.4 s
    return simulation.status_message()


def test_sensor_placement_task_4_raises_the_gain_without_the_step():
    from pathlib import Path

    from lab_modules.exercises.sensor_placement import largest_stable_gain
    exercise = get("sensor_placement")
    sheet = (Path(__file__).resolve().parents[1] / "static" / "worksheets" / "sensor_placement.md").read_text()
    task = sheet[sheet.index("4. **Integrated sensor.**"):sheet.index("\n5. ")]
    assert "reference step to 0" in task
    limit, mode = largest_stable_gain(exercise.resolve({"sensor_offset_mm": 0.0}))
    assert 1.75 < limit < 2.5
    # with the default 50 µm step the run stops on the current limit at a stable gain (the old task) ...
    kicked = _placement_stop(0.9 * limit, 50.0)
    assert "amplifier's limit" in kicked and "loop is stable" in kicked and "reference step to 0" in kicked
    # ... without it the stable gain runs on and the first unstable one stops naming its mode
    assert _placement_stop(0.95 * limit, 0.0) == ""
    unstable = _placement_stop(1.03 * limit, 0.0)
    assert f"mode {mode} grows" in unstable


# -- defect 7: kalman_noise's consistency readouts rest on enough independent samples -----------------
def test_kalman_consistency_readouts_hold_where_the_50ms_window_swung():
    from lab_modules.exercises.kalman_noise import T, consistency, setup
    from lab_modules.loops.radial_axis_experiment import AxisSimulation
    from lab_modules.loops.radial_axis_loop import TRACE_COLUMNS
    exercise = get("kalman_noise")
    windows = []
    for seed in range(3):
        values = exercise.resolve({"seed": seed})
        run = consistency(values)
        assert 0.85 <= run["mean_nees"] <= 1.15 and run["inside_3sigma_percent"] >= 99.3, (seed, run)
        assert run["independent_samples"] >= 500
        # the old readouts: 50 ms scope windows of the same kind of run
        simulation = AxisSimulation(setup(values), seed=seed)
        simulation.advance(2000)
        trace = simulation.advance(round(1.0 / T))
        column = {name: 1 + i for i, name in enumerate(TRACE_COLUMNS)}
        z = (trace[:, column["x_estimated_m"]] - trace[:, column["x_true_m"]]) / trace[:, column["x_sigma_m"]]
        n = round(0.05 / T)
        windows += [(np.mean(w**2), 100 * np.mean(np.abs(w) <= 3)) for w in z[: len(z) // n * n].reshape(-1, n)]
    nees, inside = np.array(windows).T
    assert nees.min() < 0.85 or nees.max() > 1.15      # the bound above would have failed on the scope window
    assert inside.min() < 99.3


def test_kalman_consistency_is_shown_with_its_sample_count_and_flags_a_mistuned_filter():
    exercise = get("kalman_noise")
    final = list(exercise.analyse(exercise.resolve({})))[-1]
    readouts = {label: value for label, value, _ in final.readouts}
    assert 500 <= readouts["Independent samples behind these two"] <= 3000
    overconfident = list(exercise.analyse(exercise.resolve({"filter_r_position": 7.1e-5})))[-1]
    nees = next(v for label, v, _ in overconfident.readouts if label.startswith("Mean (error/σ)²"))
    assert nees > 4.0                                 # R_x ten times too small: about 8


def test_independent_samples_of_an_ar1_sequence():
    from lab_modules.analysis import independent_samples
    rng = np.random.default_rng(1)
    rho, n = 0.9, 200_000
    x = np.empty(n)
    x[0] = 0.0
    noise = rng.standard_normal(n)
    for k in range(1, n):
        x[k] = rho * x[k - 1] + noise[k]
    expected = n * (1 - rho**2) / (1 + rho**2)       # N / (1 + 2 Σ ρ^2k)
    assert abs(independent_samples(x) / expected - 1) < 0.1
    assert abs(independent_samples(noise) / n - 1) < 0.02


# -- defect 14: every readout is a plain name with its unit and a number (or a clear word) -----------
FORMULA_MARKS = ("=", "√", "e^(", "1/L", "²h", "Kd·", "·Kp")
UNIT_WORDS = ("…", "#", ",", " and", "of ", "mode")
WORDS = ({"touched down", "not reached", "computing …", "none", "stable", "unstable"}
         | {f"mode {j}" for j in range(1, 7)} | {f"zone {z}" for z in "ABCD"})


def _check_readouts(name: str, readouts) -> None:
    import re

    from app.panels.text import readout as _format
    for label, value, unit in readouts:
        assert not any(mark in label for mark in FORMULA_MARKS), (name, label)
        assert not label.startswith("…"), (name, label)
        assert not any(word in unit for word in UNIT_WORDS), (name, label, unit)
        assert not re.search(r"\d", re.sub(r"^1/", "", unit)), (name, label, unit)   # no numbers in a unit
        if isinstance(value, str):
            assert value in WORDS, (name, label, value)
        else:
            shown = _format(value)
            assert np.isfinite(value) or np.isinf(value), (name, label, "a NaN says nothing: use a word")
            assert "e+" not in shown and "e-" not in shown, (name, label, shown)


@pytest.mark.parametrize("name", ["kalman_noise", "ekf_parameters", "ekf_disturbance", "lqg_vs_pid",
                                  "sensor_placement", "maglev_tracking", "maglev_tuning", "thrust_liftoff",
                                  "self_sensing", "stiffness_map", "adaptive_filter", "rotor_at_speed"])
def test_readouts_are_names_units_and_numbers(name):
    from lab_modules.exercises import Analysis
    exercise = get(name)
    values = exercise.resolve({})
    result = exercise.analyse(values)
    results = [result] if isinstance(result, Analysis) else list(result)
    for analysis in results:
        _check_readouts(name, analysis.readouts)
    simulation = exercise.simulation(values)
    trace = simulation.advance(max(round(0.05 / simulation.sample_time_s), 20))
    _check_readouts(name, exercise.live_readouts({c: trace[:, 1 + i] for i, c in enumerate(simulation.columns)}))


def test_readout_numbers_read_as_numbers():
    from app.panels.text import readout as _format
    assert _format(480_000.0) == "480\u202f000" and _format(1.03e6) == "1\u202f030\u202f000"
    assert _format(7.5e-8) == "7.5·10⁻⁸" and _format(240.0) == "240" and _format(-1700.0) == "-1\u202f700"
    assert _format("touched down") == "touched down" and _format(float("nan")) == "—"
