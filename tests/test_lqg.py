"""LQG regulator of paper 000, §IV (lab_modules.controllers, analysis) against
scipy and python-control, and the exercise ``lqg_vs_pid`` against the paper's
claims (Figs. 7-9)."""

import json

import control
import numpy as np
import pytest
import scipy.linalg
from scipy.optimize import linear_sum_assignment

from app.cli import main
from lab_modules import analysis
from lab_modules.controllers.lqr import (
    PAPER_LQG,
    PAPER_LQR_WEIGHTS,
    StateFeedback,
    integral_augmented_model,
    lqr,
)
from lab_modules.exercises.lqg_vs_pid import EXERCISE, SideBySide, column, setups, step_response
from lab_modules.loops.radial_axis_experiment import AxisSimulation
from lab_modules.plants.radial_bearing import RIG

T = RIG.sample_time_s
#: eq. 16-17 restricted to the fourth-order linear filter (x, v, i, x_d) of Fig. 7
PAPER_FILTER_Q = np.diag([0.0, 2.6e-10, 0.43, 0.0])
PAPER_FILTER_R = np.diag([7.1e-4, 1.4e-1])


def pole_distance(a, b):
    """Largest distance between two pole sets after optimal one-to-one pairing."""
    a, b = np.asarray(a, dtype=complex), np.asarray(b, dtype=complex)
    assert a.shape == b.shape, f"{a.size} poles vs {b.size}"
    distance = np.abs(a[:, None] - b[None, :])
    rows, cols = linear_sum_assignment(distance)
    return distance[rows, cols].max()


def gain_vector(regulator: StateFeedback) -> np.ndarray:
    """dlqr's convention u = -k z on z = (x, v, i, xi)."""
    return np.array([*regulator.state_gain, -regulator.integral_gain_v_per_m_s])


# -- design (eq. 19-21) ----------------------------------------------------------

@pytest.mark.parametrize("weights, control_weight", [
    (PAPER_LQR_WEIGHTS, 1.0),
    ((1e8, 10.0, 1e-2, 1e13), 0.1),
    ((1e5, 1.0, 1e-4, 1e10), 10.0),
])
def test_dlqr_gain_equals_scipy_dare_solution(weights, control_weight):
    """``lqr`` = eq. 21 with P_J from scipy's DARE (eq. 20), within 1e-6 relative,
    and P_J satisfies eq. 20 itself."""
    A, B = integral_augmented_model()
    Q, R = np.diag(weights), np.array([[control_weight]])
    P = scipy.linalg.solve_discrete_are(A, B, Q, R)
    expected = np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A)[0]          # eq. 21
    ours = gain_vector(lqr(weights, control_weight))
    np.testing.assert_allclose(ours, expected, rtol=1e-6)
    residual = Q + A.T @ P @ A - A.T @ P @ B @ np.linalg.solve(R + B.T @ P @ B, B.T @ P @ A) - P
    assert np.max(np.abs(residual)) <= 1e-6 * np.max(np.abs(P))


def test_paper_weights_reproduce_the_paper_gains():
    """The documented Q_J, R_J = 1 give eq. 22's K and §IV's K_I to 0.1 %;
    doubling the position weight does not (the match is not automatic)."""
    np.testing.assert_allclose(gain_vector(lqr(PAPER_LQR_WEIGHTS, 1.0)), gain_vector(PAPER_LQG), rtol=1e-3)
    heavier = (2 * PAPER_LQR_WEIGHTS[0], *PAPER_LQR_WEIGHTS[1:])
    assert np.max(np.abs(gain_vector(lqr(heavier, 1.0)) / gain_vector(PAPER_LQG) - 1)) > 0.02


def test_paper_gains_give_stable_well_damped_regulator():
    """Our reading of eq. 22 (SI state, u in volts, K_I on the integral of the
    error in metres): regulator poles python-control computes for the
    augmented loop are stable, the dominant pair damped by zeta >= 0.6, and
    the static stiffness of the state feedback K_a k_i K_x / (1 + K_a K_i) - k_x
    is a few N/µm, the order of the paper's 6.7 N/µm."""
    A, B = integral_augmented_model()
    regulator = control.ss(A - B @ gain_vector(PAPER_LQG)[None], B, np.eye(4), 0, T)
    poles_s = analysis.z_to_s(regulator.poles(), T)
    assert np.all(poles_s.real < 0)
    dominant = poles_s[np.argmax(poles_s.real)]
    assert -dominant.real / abs(dominant) >= 0.6
    K_x, _, K_i = PAPER_LQG.state_gain
    Ka = RIG.amplifier_gain_a_per_v
    stiffness = Ka * RIG.ki_n_per_a * K_x / (1 + Ka * K_i) - RIG.kx_n_per_m
    assert 2e6 <= stiffness <= 10e6


@pytest.mark.parametrize("sensor_lag_s", [0.0, 200e-6])
def test_lqg_loop_poles_are_regulator_and_filter_poles(sensor_lag_s):
    """Separation principle: with the integrator on the estimate, the poles of
    the loop assembled by ``analysis.closed_loop`` (plant, integrator, filter,
    state gain) are those of A_aug - B_aug K (python-control) together with the
    filter's error poles A - A K_f C (and the sensor lag's own pole), within 1e-6."""
    model = RIG.discrete_model(sensor_lag_s)
    n = model.nstates
    Kf, _ = analysis.steady_state_kalman(model, PAPER_FILTER_Q[:n, :n], PAPER_FILTER_R)
    state_gain = np.r_[PAPER_LQG.state_gain, np.zeros(n - 3)]          # no feedback of x_d
    loop = analysis.closed_loop(model, PAPER_LQG.integrator(), Kf, True, state_gain)
    A, B = integral_augmented_model()
    regulator = control.ss(A - B @ gain_vector(PAPER_LQG)[None], B, np.eye(4), 0, T).poles()
    Ad, C = np.asarray(model.A), np.asarray(model.C)
    filter_poles = np.linalg.eigvals(Ad - Ad @ Kf @ C)
    expected = np.concatenate([regulator, filter_poles] + ([[np.exp(-T / sensor_lag_s)]] if n == 4 else []))
    assert pole_distance(analysis.loop_poles(loop), expected) <= 1e-6


# -- the compiled loop against the linear analysis -------------------------------

@pytest.mark.parametrize("integrator_input", ["estimated", "measured"])
@pytest.mark.parametrize("test", ["reference", "disturbance"])
def test_compiled_lqg_loop_follows_python_control_response(test, integrator_input):
    """Noise-free compiled loop (linear plant, state feedback on the filter's
    estimate) against python-control's forced response of the loop that
    ``analysis.closed_loop`` assembles with the steady-state filter: the same
    rotor position within 1 % of its peak.  (The compiled filter starts from its
    initial covariance; 5 ms before the step bring it to steady state.)"""
    values = EXERCISE.resolve({"force_law": "linear", "integrator_input": integrator_input})
    axis = setups(values)["LQG"]
    reference_m, force_n = (50e-6, 0.0) if test == "reference" else (0.0, 200.0)
    trace, stop = step_response(axis, reference_m, force_n)
    assert stop == ""
    after = trace[trace[:, 0] >= 0.0]
    x_compiled = column(after, "x_true_m")
    u = np.zeros((len(analysis.LOOP_INPUTS), len(after)))
    u[0], u[1] = reference_m, force_n
    response = control.forced_response(axis.loop().system, np.arange(len(after)) * T, u)
    x_linear = np.asarray(response.outputs[analysis.LOOP_OUTPUTS.index("x_m")])
    peak = np.max(np.abs(x_linear))
    assert peak > 10e-6
    assert np.max(np.abs(x_compiled - x_linear)) <= 0.01 * peak


def test_loops_side_by_side_draw_the_same_noise():
    """Two loops in ``SideBySide`` seeded alike see identical noise: with the
    same set-up in both slots the traces agree exactly; the LQG and PID differ."""
    values = EXERCISE.resolve({"seed": 3})
    loops = setups(values)
    twins = SideBySide({"LQG": AxisSimulation(loops["LQG"], seed=3), "PID": AxisSimulation(loops["LQG"], seed=3)})
    trace = twins.advance(2000)
    columns = {name: trace[:, 1 + i] for i, name in enumerate(twins.columns)}
    np.testing.assert_array_equal(columns["x_true_m_lqg"], columns["x_true_m_pid"])
    pair = EXERCISE.simulation(values).advance(2000)
    named = dict(zip(twins.columns, pair[:, 1:].T))
    assert np.max(np.abs(named["x_true_m_lqg"] - named["x_true_m_pid"])) > 1e-7


# -- the paper's claims (§IV, Figs. 7-9) with the paper's gains ------------------

@pytest.fixture(scope="module")
def paper_metrics():
    """Headless metrics on the defaults: eq. 22 gains, eq. 16-17 filter, nonlinear plant."""
    return EXERCISE.metrics(EXERCISE.resolve({}), 0.3)


def test_metrics_carry_the_issue_names(paper_metrics):
    names = {"dynamic_stiffness_lqg_n_per_um", "dynamic_stiffness_pid_n_per_um", "overshoot_lqg_percent",
             "overshoot_pid_percent", "peak_current_lqg_a", "peak_current_pid_a",
             "dominant_pole_ratio_filter_to_lqg", "lqr_gain"}
    assert names <= paper_metrics.keys()
    np.testing.assert_allclose(paper_metrics["lqr_gain"], gain_vector(PAPER_LQG) * [1, 1, 1, -1], rtol=1e-3)


def test_filter_dominant_poles_five_times_faster_than_lqg(paper_metrics):
    """Fig. 7: the filter's dominant real part is more than 5x the regulator's."""
    assert paper_metrics["dominant_pole_ratio_filter_to_lqg"] >= 5.0


def test_lqg_peak_current_below_pid(paper_metrics):
    """Fig. 8: the LQG needs far less control current on the 50 µm step."""
    assert paper_metrics["peak_current_lqg_a"] < paper_metrics["peak_current_pid_a"]


def test_pid_overshoots_more_than_lqg(paper_metrics):
    """Fig. 8: the PID overshoots, the LQG hardly."""
    assert paper_metrics["overshoot_pid_percent"] > paper_metrics["overshoot_lqg_percent"] + 10.0


@pytest.mark.xfail(strict=True, reason=(
    "eq. 22 read in SI units gives 2.4 % overshoot (linear and nonlinear plant): the reference enters "
    "through the integrator only and the dominant pair -202 ± 216j rad/s has zeta = 0.68"))
def test_lqg_overshoot_at_most_two_percent(paper_metrics):
    """Fig. 8: "the state space controlled rotor shows no overshoot at all" (issue: <= 2 %)."""
    assert paper_metrics["overshoot_lqg_percent"] <= 2.0


@pytest.mark.xfail(strict=True, reason=(
    "eq. 22's position and velocity gains (9979 V/m, 29.7 V s/m) are below the PID's (13000 V/m, "
    "39 V s/m) and its current feedback lowers the amplifier's DC gain by 27 %: the LQG is softer "
    "(3.1 N/µm on the linear plant) and a 400 N step drives the nonlinear bearing to touchdown"))
def test_lqg_dynamic_stiffness_at_least_one_and_a_half_times_pid(paper_metrics):
    """Fig. 9: s_dyn,LQG = 6.7 N/µm against s_dyn,PID = 3.6 N/µm (issue: >= 1.5x)."""
    assert paper_metrics["dynamic_stiffness_lqg_n_per_um"] >= 1.5 * paper_metrics["dynamic_stiffness_pid_n_per_um"]


def test_cli_run_prints_parameters_model_and_metrics(capsys):
    """``python -m app run lqg_vs_pid --json``: one object with the resolved
    parameters, the filter and regulator matrices, and the metrics."""
    assert main(["run", "lqg_vs_pid", "--json", "--duration", "0.2", "--set", "lqg_gains=LQR from Q_J, R_J"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["exercise"] == "lqg_vs_pid"
    assert result["parameters"]["lqg_gains"] == "LQR from Q_J, R_J"
    assert np.array(result["model"]["A_aug"]).shape == (4, 4)
    np.testing.assert_allclose(result["model"]["state_gain_K"], result["metrics"]["lqr_gain"][:3])


def test_weight_out_of_range_is_one_line_error(capsys):
    assert main(["run", "lqg_vs_pid", "--set", "r_control=0"]) == 2
    err = capsys.readouterr().err.strip()
    assert "r_control" in err and "0.001" in err and "\n" not in err


def test_stiffer_weights_of_the_worksheet_reach_the_papers_lqg_figures():
    """Worksheet task 4 (q_x, q_v x100, q_xi x30): no overshoot (<= 2 %), the
    filter still 5x faster, far less current than the PID, and the paper's
    s_dyn,LQG = 6.7 N/µm within 5 % on the nonlinear plant."""
    w = PAPER_LQR_WEIGHTS
    values = EXERCISE.resolve({"lqg_gains": "LQR from Q_J, R_J", "q_position": 100 * w[0],
                               "q_velocity": 100 * w[1], "q_current": w[2], "q_integral": 30 * w[3]})
    metrics = EXERCISE.metrics(values, 0.05)
    assert metrics["overshoot_lqg_percent"] <= 2.0
    assert metrics["dominant_pole_ratio_filter_to_lqg"] >= 5.0
    assert metrics["peak_current_lqg_a"] < 0.1 * metrics["peak_current_pid_a"]
    assert metrics["dynamic_stiffness_lqg_n_per_um"] == pytest.approx(6.7, rel=0.05)
