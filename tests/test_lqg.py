"""LQG regulator of paper 000, §IV (lab_modules.controllers, analysis) against
scipy and python-control, and the exercise ``lqg_vs_pid`` against the paper's
claims (Figs. 7-9)."""

import json
import pathlib

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
from lab_modules.exercises import lqg_vs_pid
from lab_modules.exercises.lqg_vs_pid import EXERCISE, setups
from lab_modules.loops.radial_axis_experiment import AxisSimulation
from lab_modules.loops.radial_axis_side_by_side import SideBySide
from lab_modules.loops.radial_axis_step_tests import column, step_response
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

@pytest.mark.parametrize("loop_name, overrides", [
    ("LQG", {"integrator_input": "estimated"}), ("LQG", {"integrator_input": "measured"}),
    ("PID", {"pid_structure": "I-PD"})])
@pytest.mark.parametrize("test", ["reference", "disturbance"])
def test_compiled_loop_follows_python_control_response(test, loop_name, overrides):
    """Noise-free compiled loop (linear plant, state feedback on the filter's
    estimate) against python-control's forced response of the loop that
    ``analysis.closed_loop`` assembles with the steady-state filter: the same
    rotor position within 1 % of its peak.  (The compiled filter starts from its
    initial covariance; 5 ms before the step bring it to steady state.)  The
    I-PD runs its reference filter in the compiled loop and in front of the
    python-control loop (``analysis.with_reference_filter``)."""
    values = EXERCISE.resolve({"force_law": "linear", **overrides})
    axis = setups(values)[loop_name]
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
             "dominant_pole_ratio_filter_to_lqg", "lqr_gain",
             *(f"{figure}_{loop}_{unit}" for loop in ("lqg", "pid") for figure, unit in (
                 ("step_stiffness", "n_per_um"), ("min_dynamic_stiffness", "n_per_um"),
                 ("min_dynamic_stiffness_frequency", "hz"))),
             "redesign_step_stiffness_lqg_n_per_um", "redesign_overshoot_lqg_percent",
             "redesign_peak_current_lqg_a", "redesign_dominant_pole_ratio_filter_to_lqg"}
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


# -- the lab's own figures: two stiffness definitions, no NaN, redesign, fronts -----------

def test_default_metrics_have_no_unexplained_gaps(paper_metrics):
    """``run lqg_vs_pid --json`` at the defaults: every metric is a finite number
    except the time-run figures of a step test that lost the rotor, which are
    null, and that loop's status names the touchdown and the largest step it
    holds.  The linear-loop stiffnesses are numbers for both loops."""
    def numbers(value):
        if isinstance(value, (list, tuple)):
            return [n for v in value for n in numbers(v)]
        return [value] if isinstance(value, float) else []
    assert all(np.isfinite(n) for value in paper_metrics.values() for n in numbers(value))
    for loop in ("lqg", "pid"):
        gaps = [key for key, value in paper_metrics.items() if value is None]
        own = [key for key in gaps if f"_{loop}_" in key]
        status = paper_metrics[f"step_test_status_{loop}"]
        if own:
            assert "Touchdown" in status and f"{paper_metrics[f'largest_disturbance_step_{loop}_n']:.0f} N" in status
        for figure in ("step_stiffness", "min_dynamic_stiffness"):
            assert paper_metrics[f"{figure}_{loop}_n_per_um"] > 0
    assert {key for key, value in paper_metrics.items() if value is None} == {
        "dynamic_stiffness_lqg_n_per_um", "max_deviation_lqg_um", "offset_after_disturbance_lqg_um"}


def test_largest_disturbance_step_is_the_edge_of_touchdown():
    """The LQG on the nonlinear plant holds the step ``largest_disturbance_step``
    reports and loses the rotor one resolution step above it."""
    axis = setups(EXERCISE.resolve({}))["LQG"]
    largest = lqg_vs_pid.largest_disturbance_step(axis)
    assert 0 < largest < 400
    assert step_response(axis, 0.0, largest)[1] == ""
    assert "Touchdown" in step_response(axis, 0.0, largest + lqg_vs_pid.LARGEST_STEP_RESOLUTION_N)[1]


@pytest.mark.parametrize("loop_name", ["LQG", "PID"])
def test_step_stiffness_of_the_linear_loop_equals_the_compiled_time_run(loop_name):
    """Two implementations of Fig. 9's s_dyn agree: the linear loop's step
    stiffness (compiled recursion, 300 ms) and the compiled noise-free run on
    the linear plant (150 ms, filter from its start-up covariance), within 1 %;
    the minimum dynamic stiffness lies at a finite frequency below Nyquist."""
    values = EXERCISE.resolve({"force_law": "linear"})
    axis = setups(values)[loop_name]
    figures = lqg_vs_pid.loop_figures(axis)
    trace, stop = step_response(axis, 0.0, 400.0)
    assert stop == ""
    time_run = lqg_vs_pid.disturbance_step_figures(trace, 400.0)["dynamic_stiffness_n_per_m"]
    assert figures["step_stiffness_n_per_m"] == pytest.approx(time_run, rel=0.01)
    assert 1.0 < figures["min_dynamic_stiffness_frequency_hz"] < 0.5 / T


def test_i_pd_keeps_the_stiffness_and_drops_the_step_current():
    """The I-PD is the same feedback loop (same stiffness and noise), but the
    reference enters through the integral only: the peak current on the 50 µm
    step falls from ~12 A to the ~0.31 A that holds the rotor there, as low as the LQG's."""
    plain = lqg_vs_pid.loop_figures(setups(EXERCISE.resolve({}))["PID"])
    ipd = lqg_vs_pid.loop_figures(setups(EXERCISE.resolve({"pid_structure": "I-PD"}))["PID"])
    for key in ("step_stiffness_n_per_m", "min_dynamic_stiffness_n_per_m", "noise_rms_current_a"):
        assert ipd[key] == pytest.approx(plain[key], rel=1e-9)
    step_m = 50e-6
    assert plain["peak_current_a_per_m"] * step_m > 8.0
    assert ipd["peak_current_a_per_m"] * step_m < 0.4
    holding = step_m * RIG.kx_n_per_m / RIG.ki_n_per_a             # current that holds x = 50 µm
    assert ipd["peak_current_a_per_m"] * step_m >= 0.99 * holding


def test_redesign_preset_is_the_lqr_of_its_weights():
    """The named preset = dlqr of the paper's weights ×316 on x and v, ×10 on ∫e."""
    values = EXERCISE.resolve({"lqg_gains": "redesign preset"})
    preset = lqg_vs_pid.regulator(values)
    w = PAPER_LQR_WEIGHTS
    expected = lqr((316 * w[0], 316 * w[1], w[2], 10 * w[3]), 1.0)
    np.testing.assert_allclose(gain_vector(preset), gain_vector(expected), rtol=1e-12)
    assert preset.state_gain[0] > 5 * PAPER_LQG.state_gain[0]          # a much stiffer state feedback


def test_pareto_front_and_its_readings():
    """The front keeps the designs no other beats at no more cost, and the two
    readings interpolate along it (log cost) or say NaN outside it."""
    cost = np.array([1.0, 2.0, 3.0, 4.0, 0.5])
    stiffness = np.array([2.0, 1.0, 5.0, 4.0, 1.5])
    np.testing.assert_array_equal(lqg_vs_pid.pareto(cost, stiffness), [4, 0, 2])
    assert lqg_vs_pid.stiffness_at(cost, stiffness, 1.0) == pytest.approx(2.0)
    assert lqg_vs_pid.stiffness_at(cost, stiffness, np.sqrt(3.0)) == pytest.approx(3.5)
    assert np.isnan(lqg_vs_pid.stiffness_at(cost, stiffness, 10.0))
    assert lqg_vs_pid.cost_of(cost, stiffness, 3.5) == pytest.approx(np.sqrt(3.0))
    assert lqg_vs_pid.cost_of(cost, stiffness, 1.0) == pytest.approx(0.5)
    assert np.isnan(lqg_vs_pid.cost_of(cost, stiffness, 6.0))


def test_fronts_contain_the_paper_designs():
    """The LQG sweep passes through the paper's weights (factors 1, 1): that design
    has eq. 22's stiffness and noise current; the PID sweep through the printed PID."""
    values = EXERCISE.resolve({})
    lqg, pid_family = lqg_vs_pid.fronts(values)
    loops = setups(values)
    factors = lqg_vs_pid.FRONT_LQG_FACTORS
    one = int(np.argmin(np.abs(np.log(factors))))
    assert factors[one] == pytest.approx(1.0)
    paper = lqg_vs_pid.loop_figures(loops["LQG"])
    k = one * factors.size + one
    assert lqg.step_stiffness_n_per_m[k] == pytest.approx(paper["step_stiffness_n_per_m"], rel=1e-3)
    assert lqg.noise_rms_current_a[k] == pytest.approx(paper["noise_rms_current_a"], rel=1e-3)
    printed = lqg_vs_pid.loop_figures(loops["PID"])
    assert np.nanmin(np.abs(pid_family.step_stiffness_n_per_m / printed["step_stiffness_n_per_m"] - 1)) < 1e-9


def test_analysis_yields_quick_result_then_fronts():
    """The Analysis tab: the first result comes without the sweep and has the
    same plots (empty fronts) as the last, which has the fronts filled in.  The
    browser keeps titles, series and colours of the first result, so they agree."""
    results = list(EXERCISE.analyse(EXERCISE.resolve({})))
    first, last = results[0], results[-1]

    def styles(result):
        return [(p.title, [(label, color) for label, _, color in p.series]) for p in result.plots]
    assert styles(first) == styles(last)
    assert len({color for p in last.plots if p.title.startswith("Trade-off") for _, _, color in p.series}) >= 5
    fronts = [p for p in last.plots if p.title.startswith("Trade-off front")]
    assert len(fronts) == 3
    for plot in fronts:
        assert np.all(np.diff(plot.x) >= 0) and plot.points and plot.log_x
        assert np.isfinite(np.asarray(plot.series[0][1])).sum() > 10
    labels = [label for label, _, _ in last.readouts]
    assert not [label for label in labels if "|" in label]          # a readout is a markdown table row
    assert any(label.startswith("Fronts:") for label in labels)
    assert any("largest disturbance step held" in label for label in labels)


@pytest.mark.parametrize("claim", lqg_vs_pid.CLAIMS, ids=lambda c: c.quantity)
def test_claims_hold(claim, claim_metrics):
    """Every paper-vs-lab claim of the exercise is met at its settings."""
    value = claim.value_in(claim_metrics(claim))
    assert claim.holds(value), f"{claim.metric} = {value} outside {claim.accept_text()}"


@pytest.fixture(scope="module")
def claim_metrics():
    """Metrics per claim settings, computed once per distinct setting."""
    cache = {}

    def measure(claim):
        key = tuple(sorted(claim.settings.items()))
        if key not in cache:
            duration = claim.duration_s or 0.2
            cache[key] = EXERCISE.metrics(EXERCISE.resolve(dict(claim.settings)), duration)
        return cache[key]
    return measure


def test_worksheet_has_the_claims_marker():
    """The paper-vs-lab table is rendered from ``CLAIMS`` at the marker line."""
    root = pathlib.Path(lqg_vs_pid.__file__).resolve().parents[2]
    worksheet = (root / "static" / "worksheets" / EXERCISE.worksheet).read_text(encoding="utf-8")
    assert "<!-- claims -->" in worksheet.splitlines()

