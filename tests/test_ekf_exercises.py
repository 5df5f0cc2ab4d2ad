"""The "done when" numbers of the EKF exercises (paper 000, §III) and their
command-line contract."""

import json

import numpy as np
import pytest

from app.cli import main
from lab_modules.exercises import ekf_disturbance, ekf_parameters, results
from lab_modules.loops.radial_axis_ekf_loop import TOUCHDOWN, EKFLoopSimulation, column
from lab_modules.parameters import ParameterError

DISTURBANCE = ekf_disturbance.EXERCISE
PARAMETERS = ekf_parameters.EXERCISE


@pytest.fixture(scope="module")
def disturbance_metrics():
    return DISTURBANCE.metrics(DISTURBANCE.resolve(), DISTURBANCE.default_duration_s)


@pytest.fixture(scope="module")
def parameter_metrics():
    return PARAMETERS.metrics(PARAMETERS.resolve(), PARAMETERS.default_duration_s)


def test_force_estimate_settles_within_5_percent_of_a_400_n_step(disturbance_metrics):
    m = disturbance_metrics
    assert DISTURBANCE.resolve()["disturbance_step_n"] == 400.0
    assert m["status_force_step"] == "ok"
    assert 0.0 < m["disturbance_estimate_settling_ms"] < 50.0      # settles, inside the 200 ms run
    assert abs(m["disturbance_estimate_final_error_percent"]) < 5.0


def test_q55_trades_speed_against_noise_as_in_fig_4():
    slow = ekf_disturbance.force_step(DISTURBANCE.resolve({"filter_q_force": 0.01}))
    fast = ekf_disturbance.force_step(DISTURBANCE.resolve({"filter_q_force": 100.0}))
    assert fast["settling_ms"] < slow["settling_ms"]
    assert fast["noise_n"] > 3 * slow["noise_n"]


def test_force_feedforward_reduces_the_displacement_after_the_step():
    without = ekf_disturbance.force_step(DISTURBANCE.resolve({"feedforward": "off"}))
    with_ff = ekf_disturbance.force_step(DISTURBANCE.resolve({"feedforward": "on"}))
    assert with_ff["peak_displacement_um"] < 0.9 * without["peak_displacement_um"]


def test_factors_from_phi_stay_within_2_percent_across_the_200_n_sweep(disturbance_metrics):
    m = disturbance_metrics
    assert DISTURBANCE.resolve()["sweep_load_n"] == 200.0
    assert m["status_gap_sweep"] == "ok"
    low, high = m["sweep_kx_range_n_per_um"]
    assert high / low > 2.0                          # the sweep really moves the operating point
    assert m["kx_from_phi_max_error_percent"] < 2.0
    assert m["ki_from_phi_max_error_percent"] < 2.0


def test_paper_current_noise_q33_spoils_the_factors_from_phi():
    sweep = ekf_disturbance.gap_sweep(DISTURBANCE.resolve({"filter_q_current": 0.43}))
    assert sweep["kx_rms_error_percent"] > 5.0


def test_prbs_excitation_lets_ki_and_kx_converge_within_5_percent(parameter_metrics):
    m = parameter_metrics
    assert m["status"] == "ok"
    assert abs(m["ki_estimate_error_percent"]) < 5.0
    assert abs(m["kx_estimate_error_percent"]) < 5.0
    assert m["ki_converged"] and m["kx_converged"]


def test_without_excitation_ki_and_kx_do_not_converge(parameter_metrics):
    m = parameter_metrics
    assert m["status_no_excitation"] == "ok"
    assert abs(m["ki_estimate_error_percent_no_excitation"]) > 5.0
    assert abs(m["kx_estimate_error_percent_no_excitation"]) > 5.0
    assert not (m["ki_converged_no_excitation"] or m["kx_converged_no_excitation"])
    # k_x is not observable without excitation: its 3-sigma band stays wide
    assert m["kx_estimate_3sigma_percent_no_excitation"] > 5 * m["kx_estimate_3sigma_percent"]


def test_scope_trace_has_the_declared_columns_and_bands():
    for exercise in (PARAMETERS, DISTURBANCE):
        sim = exercise.simulation(exercise.resolve())
        trace = sim.advance(200)
        assert trace.shape == (200, 1 + len(sim.columns))
        for chart in exercise.charts:
            for series in chart.series:
                assert series.column in sim.columns
        assert sim.status_message() == ""
        readouts = exercise.live_readouts({name: trace[:, 1 + i] for i, name in enumerate(sim.columns)})
        assert readouts and all(np.isfinite(value) for _, value, _ in readouts)


@pytest.mark.parametrize("exercise", [PARAMETERS, DISTURBANCE], ids=lambda e: e.name)
def test_filter_covariance_stays_symmetric_positive_definite_in_the_loop(exercise):
    sim = exercise.simulation(exercise.resolve())
    sim.advance(20000)
    assert sim.status_message() == ""
    sigma = np.sqrt(np.diag(sim.P))
    assert np.array_equal(sim.P, sim.P.T)
    assert np.linalg.eigvalsh(sim.P / np.outer(sigma, sigma)).min() > 0


def test_unstable_settings_stop_with_a_message():
    sim = EKFLoopSimulation(ekf_parameters.setup(PARAMETERS.resolve({"pid_gain": 0.05})), seed=0)
    sim.advance(20000)
    assert sim.status == TOUCHDOWN
    assert "Touchdown" in sim.status_message()
    assert len(sim.advance(10)) == 0


def test_analysis_has_fig_5_plots_and_consistent_readouts():
    values = DISTURBANCE.resolve()
    result = list(results(DISTURBANCE.analyse(values)))[-1]        # the fullest result
    titles = [plot.title for plot in result.plots]
    assert sum("Fig. 5" in t for t in titles) == 3 and sum("Fig. 4" in t for t in titles) == 1
    for plot in result.plots:
        assert np.all(np.diff(plot.x) > 0)
        assert all(len(y) == len(plot.x) for _, y, _ in plot.series)
    assert np.all(result.poles["filter error (at x = 0)"].real < 0)


def test_true_local_values_in_the_trace_are_eq_10_derivatives():
    sim = PARAMETERS.simulation(PARAMETERS.resolve())
    trace = sim.advance(500)
    from lab_modules.plants.radial_bearing import RIG
    k = 400
    kx, ki = RIG.local_factors(column(trace, "x_true_m")[k], column(trace, "current_a")[k])
    assert column(trace, "kx_true_n_per_m")[k] == pytest.approx(kx, rel=1e-12)
    assert column(trace, "ki_true_n_per_a")[k] == pytest.approx(ki, rel=1e-12)


@pytest.mark.parametrize("overrides", [{"filter_q_force": -1}, {"filter_sensor_lag_us": 0},
                                       {"feedforward": "maybe"}])
def test_bad_values_are_one_line_errors(overrides):
    with pytest.raises(ParameterError, match="expected"):
        DISTURBANCE.resolve(overrides)


@pytest.mark.parametrize("name, metric", [("ekf_disturbance", "disturbance_estimate_settling_ms"),
                                          ("ekf_parameters", "ki_estimate_error_percent_no_excitation")])
def test_cli_run_json_contract(name, metric, capsys):
    assert main(["run", name, "--duration", "0.3", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert set(result) == {"exercise", "parameters", "model", "metrics"}
    assert result["exercise"] == name
    assert metric in result["metrics"]
    assert len(result["model"]["states"]) == 5


def test_cli_rejects_bad_values_with_one_line(capsys):
    assert main(["run", "ekf_parameters", "--set", "prbs_amplitude_um=99", "--json"]) == 2
    error = capsys.readouterr().err
    assert "prbs_amplitude_um" in error and "0 ... 30 µm" in error
    assert len(error.strip().splitlines()) == 1


def test_retune_carries_on_and_restarts_a_new_experiments_inputs_now():
    values = DISTURBANCE.resolve()
    sim = DISTURBANCE.simulation(values)
    sim.advance(2000)
    x_hat = sim.x_hat.copy()
    faster = DISTURBANCE.retune(sim, {**values, "filter_q_force": 10.0})
    assert faster.time_s == sim.time_s and np.array_equal(faster.x_hat, x_hat)
    sweep = DISTURBANCE.retune(faster, {**values, "experiment": "gap_sweep"})
    trace = sweep.advance(10)
    assert trace[0, 0] == pytest.approx(sim.time_s)
    assert column(trace, "reference_m")[0] == 0.0            # the sweep starts from the centre
    assert column(trace, "force_true_n")[-1] < 0.01 * values["sweep_load_n"]   # the load ramps in
    restarted = PARAMETERS.retune(PARAMETERS.simulation(PARAMETERS.resolve()),
                                  PARAMETERS.resolve({"initial_ki_n_per_a": 150.0}))
    assert restarted.x_hat[3] == 150.0
