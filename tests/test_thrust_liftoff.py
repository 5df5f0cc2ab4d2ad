"""Paper 003's thrust bearing: Table 1 and the choices derived from it, the
Taylor discretisation against the exact one, the filter against filterpy, the
linear loop against the compiled one, the issue's targets (as the exercise's
claims), the unstable-Kp stop and bad command-line input."""

import functools
import json
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import control
import numpy as np
import pytest
import scipy.linalg
from filterpy.kalman import KalmanFilter as FilterpyKalmanFilter

from lab_modules.estimators.thrust_kalman import PAPER_Q_N2, ThrustFilterDesign, process_noise_from_p0
from lab_modules.exercises._thrust_liftoff_labels import liftoff_gap_evidence, median_standard_error
from lab_modules.exercises.thrust_liftoff import EXERCISE, setup
from lab_modules.loops.thrust_liftoff_linear import linear_loop
from lab_modules.loops.thrust_liftoff_loop import (
    NO_LIFTOFF,
    TOUCHDOWN,
    ThrustSetup,
    ThrustSimulation,
)
from lab_modules.plants.thrust_bearing import PAPER_P0, TABLE_1, current_loop, discrete_current_loop

REPO = Path(__file__).resolve().parents[1]
T = TABLE_1.sample_time_s


# -- Table 1 and what the lab derives from it ---------------------------------------------

def test_bias_current_force_constant_and_open_loop_pole():
    assert TABLE_1.bias_current_a == pytest.approx(0.670, abs=5e-4)
    assert TABLE_1.force_constant_n_m2_per_a2 == pytest.approx(1.08e-3, rel=2e-3)
    assert TABLE_1.open_loop_pole_rad_per_s == pytest.approx(127.9, abs=0.05)
    A, _, _ = TABLE_1.continuous_model()
    assert np.sort(np.linalg.eigvals(A).real) == pytest.approx([-127.86, 127.86], abs=0.01)
    assert TABLE_1.critical_proportional_gain_a_per_m * 1e-3 == pytest.approx(0.893, abs=5e-4)


def test_nonlinear_force_law_linearises_to_table_1():
    """Central differences of eq. 2 at (i0, x0) give k_i = 5143 N/A and k_x = −4594.1 N/mm (eq. 4)."""
    h_i, h_x = 1e-4, 1e-9
    k_i = (TABLE_1.magnetic_force_n(h_i, 0.0) - TABLE_1.magnetic_force_n(-h_i, 0.0)) / (2 * h_i)
    k_x = -(TABLE_1.magnetic_force_n(0.0, h_x) - TABLE_1.magnetic_force_n(0.0, -h_x)) / (2 * h_x)
    assert k_i == pytest.approx(5143.0, rel=1e-6)
    assert k_x == pytest.approx(-4594.1e3, rel=1e-6)
    assert TABLE_1.magnetic_force_n(0.0, 0.0) == pytest.approx(0.0, abs=1e-9)


def test_taylor_discretisation_against_the_matrix_exponential():
    """Eq. 9-11 against expm: they differ by about 3e-5 (relative), and the difference
    is the next term of the series, (AT)³/6 for Φ."""
    Phi, B_d, G_d = TABLE_1.taylor_discretisation()
    Phi_e, B_e, _ = TABLE_1.exact_discretisation()
    A, _, _ = TABLE_1.continuous_model()
    assert np.allclose(Phi_e, scipy.linalg.expm(A * T), rtol=1e-13, atol=1e-15)
    relative = np.abs(Phi - Phi_e).max() / np.abs(Phi_e).max()
    assert 1e-5 < relative < 1e-4
    assert np.abs(B_d - B_e).max() / np.abs(B_e).max() == pytest.approx(2.7e-5, rel=0.05)
    AT = A * T
    assert np.allclose(Phi_e - Phi, AT @ AT @ AT / 6, rtol=1e-3, atol=2e-9)   # diagonal: (AT)⁴/24 ≈ 1e-9
    # the paper's closed forms below eq. 11
    m, k_x, k_i = TABLE_1.mass_kg, TABLE_1.displacement_stiffness_n_per_m, TABLE_1.current_stiffness_n_per_a
    assert Phi == pytest.approx(np.array([[1 - k_x * T**2 / (2 * m), T], [-k_x * T / m, 1 - k_x * T**2 / (2 * m)]]))
    assert B_d == pytest.approx([k_i * T**2 / (2 * m), k_i * T / m])
    assert G_d == pytest.approx([T**2 / (2 * m), T / m])


def test_printed_p0_is_one_step_of_process_noise():
    """P0 is rank one and equals G_d Q G_d^T with Q ≈ 2.64e6 N² (entries within 0.5 %)."""
    # rank one to the three printed digits: correlation of x and v above 0.998
    assert PAPER_P0[0, 1] / np.sqrt(PAPER_P0[0, 0] * PAPER_P0[1, 1]) > 0.998
    Q = process_noise_from_p0()
    assert Q == pytest.approx(2.64e6, rel=5e-3)
    _, _, G_d = TABLE_1.taylor_discretisation()
    assert np.allclose(Q * np.outer(G_d, G_d), PAPER_P0, rtol=5e-3, atol=0)


def test_discrete_current_loop_matches_g_of_s():
    """G(s) of §3.1: DC gain 0.974, and the ZOH discretisation keeps it."""
    G = current_loop()
    assert float(control.dcgain(G)) == pytest.approx(7.237e5 / 7.43e5)
    A, B, C, D = discrete_current_loop(T)
    dc = C @ np.linalg.solve(np.eye(2) - A, B) + D
    assert dc == pytest.approx(7.237e5 / 7.43e5, rel=1e-9)


# -- the filter ------------------------------------------------------------------------------

def test_filter_matches_filterpy_step_by_step():
    """The compiled filter (eq. 14-18, standard form) and filterpy's KalmanFilter give the
    same estimates, covariances and gains over 300 steps of a lift-off-like input."""
    design = ThrustFilterDesign(PAPER_Q_N2, (5e-6) ** 2)
    lab = design.filter()
    Phi, B_d, Q_d = design.matrices
    ref = FilterpyKalmanFilter(dim_x=2, dim_z=1, dim_u=1)
    ref.F, ref.B, ref.H = Phi.copy(), B_d.reshape(2, 1), np.array([[1.0, 0.0]])
    ref.Q, ref.R = Q_d.copy(), np.array([[design.measurement_variance_m2]])
    ref.x, ref.P = np.array([[-0.75e-3], [0.0]]), PAPER_P0.copy()
    rng = np.random.default_rng(3)
    x = np.array([-0.75e-3, 0.0])
    Phi_e, B_e, _ = TABLE_1.exact_discretisation()
    for k in range(300):
        z = x[0] + 5e-6 * rng.standard_normal()
        lab.update([z])
        ref.update(np.array([[z]]))
        assert np.allclose(lab.x, ref.x.ravel(), rtol=1e-9, atol=1e-15), k
        assert np.allclose(lab.covariance, ref.P, rtol=1e-7, atol=1e-24), k
        assert np.allclose(lab.gain[0, :2], ref.K.ravel(), rtol=1e-7), k
        i = 2.0 - 3000.0 * x[0] + 0.3 * rng.standard_normal()
        lab.predict(i)
        ref.predict(u=np.array([[i]]))
        x = Phi_e @ x + B_e * i


def test_gain_history_converges_to_the_riccati_solution():
    design = ThrustFilterDesign()
    gains, covariances = design.gain_history(3000)
    gain, _, P_corr = design.steady_state
    assert gains[-1] == pytest.approx(gain, rel=1e-6)
    assert covariances[-1] == pytest.approx(P_corr, rel=1e-6)
    # eq. 16 at k = 0 from P0: K = P0[:, 0] / (P0[0, 0] + R)
    assert gains[0] == pytest.approx(PAPER_P0[:, 0] / (PAPER_P0[0, 0] + (5e-6) ** 2))
    assert np.all(np.abs(design.error_poles()) < 1.0)


# -- the loop --------------------------------------------------------------------------------

@pytest.mark.parametrize("use_estimate", [False, True])
def test_linear_loop_noise_prediction_matches_the_compiled_loop(use_estimate):
    """Lyapunov std of z / x̂ / current command on ``linear_loop`` against 4 s of the compiled loop
    started at the centre (no lift-off transient), within 6 %."""
    s = ThrustSetup(use_estimate=use_estimate, start_position_m=0.0, force_noise_n=200.0)
    predicted = linear_loop(s).output_std(s.sensor_noise_m, s.force_noise_n)
    trace = ThrustSimulation(s, seed=11).run(4.0)
    after = trace["time_s"] > 0.5
    for column in ("x_true_m", "x_measured_m", "x_estimated_m", "current_command_a"):
        assert np.std(trace[column][after]) == pytest.approx(predicted[column], rel=0.06), column


def test_touchdown_bearing_holds_the_collar_without_current():
    """No PID action (Kp = 0.1 A/mm, no I, no D): the collar cannot leave the stop; the run says so."""
    s = ThrustSetup(proportional_a_per_m=100.0, integral_a_per_m_s=0.0, derivative_a_s_per_m=0.0)
    sim = ThrustSimulation(s)
    trace = sim.run(1.0)
    assert sim.status == NO_LIFTOFF
    assert np.all(trace["x_true_m"] >= -0.75e-3) and np.max(trace["x_true_m"]) < -0.74e-3
    assert "no lift-off" in sim.status_message()


def test_relaunch_starts_again_from_the_stop():
    sim = ThrustSimulation(ThrustSetup(noise_on=False), relaunch_s=0.3)
    rows = np.concatenate([sim.advance(1234) for _ in range(6)])
    assert np.all(np.diff(rows[:, 0]) > 0)
    x = rows[:, 1]
    assert x[0] == x[3000] == x[6000] == -0.75e-3
    assert abs(x[2999]) < 20e-6


@pytest.mark.parametrize("kp", [0.5, 0.85, 0.89])
def test_kp_below_critical_is_unstable_and_stops_with_a_clear_message(kp):
    """Kp < |k_x|/k_i = 0.893 A/mm (others default): negative net stiffness, the collar
    ends on the touchdown bearing and the run stops saying why."""
    values = EXERCISE.resolve({"kp_a_per_mm": kp})
    assert not linear_loop(setup(values)).stable()
    sim = EXERCISE.simulation(values)
    sim.advance(round(2.0 / T))
    message = sim.status_message()
    assert sim.status in (TOUCHDOWN, NO_LIFTOFF)
    assert "unstable" in message and "0.893 A/mm" in message


def test_default_gains_are_stable_and_per_metre_they_are_not():
    """Only the mm reading of the PID gains is stable (worksheet Task 2)."""
    assert linear_loop(ThrustSetup()).stable()
    per_metre = ThrustSetup(proportional_a_per_m=3.0, integral_a_per_m_s=10.0, derivative_a_s_per_m=0.022)
    assert not linear_loop(per_metre).stable()


def test_filter_outside_the_loop_does_not_move_the_poles():
    """Measured feedback: the loop's poles are the regulator's plus the filter's error poles."""
    s = ThrustSetup()
    loop = np.sort_complex(linear_loop(s).poles())
    parts = np.sort_complex(np.concatenate([linear_loop(s, with_filter=False).poles(), s.design.error_poles()]))
    assert np.allclose(loop, parts, atol=1e-9)


def test_nonlinear_plant_and_vertical_variant_still_lift_off():
    for change in ({"nonlinear": True}, {"vertical": True, "use_estimate": True}):
        sim = ThrustSimulation(replace(ThrustSetup(noise_on=False), **change))
        trace = sim.run(2.0)
        assert sim.status_message() == "", change
        assert abs(trace["x_true_m"][-1]) < 10e-6, change


# -- the issue's targets, as the exercise's claims ------------------------------------------

@functools.cache
def claim_metrics(settings: str, duration_s: float) -> dict:
    """The metrics of one setting, once for all the claims measured there."""
    return EXERCISE.metrics(EXERCISE.resolve(json.loads(settings)), duration_s)


@pytest.mark.parametrize("claim", EXERCISE.claims, ids=lambda c: f"{c.metric}{c.settings or ''}")
def test_claim_holds(claim):
    metrics = claim_metrics(json.dumps(claim.settings, sort_keys=True), claim.duration_s or EXERCISE.default_duration_s)
    value = claim.value_in(metrics)
    assert claim.holds(value), (claim.quantity, value, claim.accept_text())


def test_harsh_sensor_makes_the_current_limit_chatter():
    """σ_v = 35 µm: the raw-measurement PID's command sits at the 10 A limit a large share
    of the time (the D term's noise alone is Kd·√2·σ_v/T ≈ 11 A); the filter-PID's does not."""
    metrics = EXERCISE.metrics(EXERCISE.resolve({"sensor_noise_um": 35.0, "seeds": 4}), 1.0)
    assert metrics["time_at_current_limit_percent_measured_feedback"] > 20.0
    assert metrics["time_at_current_limit_percent_estimated_feedback"] < 1.0


def test_headless_metrics_have_the_issue_keys():
    metrics = EXERCISE.metrics(EXERCISE.resolve({"seeds": 1}), 1.2)
    for key in ("liftoff_overshoot_percent_measured_feedback", "liftoff_overshoot_percent_estimated_feedback",
                "liftoff_peak_time_ms", "settling_time_2pct_s", "steady_std_ratio", "current_noise_ratio",
                "estimate_within_3sigma_percent", "steady_state_kalman_gain", "bias_current_a"):
        assert key in metrics, key
    json.dumps(metrics)
    assert len(EXERCISE.claims) >= 3


# -- command line ---------------------------------------------------------------------------

def run_app(*argv):
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return subprocess.run([sys.executable, "-m", "app", *argv], check=False, cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=300)


def test_cli_run_json():
    result = run_app("run", "thrust_liftoff", "--set", "seeds=1", "--duration", "1.2", "--json")
    assert result.returncode == 0, result.stderr
    metrics = json.loads(result.stdout)["metrics"]
    assert metrics["liftoff_overshoot_percent_measured_feedback"] == pytest.approx(4.4, abs=0.3)
    assert metrics["bias_current_a"] == pytest.approx(0.670, abs=5e-4)


@pytest.mark.parametrize("setting, token", [
    ("kp_a_per_mm=-1", "0.1 ... 10 A/mm"),
    ("sensor_noise_um=nan", "0 ... 50 µm"),
    ("feedback=kalman", "measured, estimated"),
    ("current_limit_a=abc", "0.5 ... 20 A"),
])
def test_cli_bad_input_exits_2_with_one_line(setting, token):
    result = run_app("run", "thrust_liftoff", "--set", setting, "--json")
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and setting.split("=")[0] in lines[0] and token in lines[0], result.stderr
    assert result.stdout == ""


# -- honest labels: the lift-off gap's cause, a median's standard error -------------------------------
def test_the_stop_not_the_taylor_model_separates_the_noise_free_liftoffs():
    gap = liftoff_gap_evidence(setup(EXERCISE.resolve({})), 0.6)
    assert gap["exact_filter_on_stop_um"] == pytest.approx(gap["taylor_filter_on_stop_um"], rel=0.01)
    assert gap["taylor_filter_on_stop_um"] > 100 * gap["taylor_filter_off_stop_um"]
    assert gap["exact_filter_off_stop_um"] < 1e-6


def test_filter_model_control_gives_the_exact_matrices():
    design = setup(EXERCISE.resolve({"filter_model": "exact ZOH"})).design
    Phi, B_d, _ = design.matrices
    Phi_e, B_e, _ = design.bearing.exact_discretisation()
    assert np.array_equal(Phi, Phi_e) and np.array_equal(B_d, B_e)
    assert not np.array_equal(setup(EXERCISE.resolve({})).design.matrices[0], Phi_e)


def test_median_standard_error_matches_the_spread_of_medians():
    rng = np.random.default_rng(3)
    medians = np.median(rng.normal(60.0, 10.0, (4000, 40)), axis=1)
    sample = rng.normal(60.0, 10.0, 40)
    assert median_standard_error(sample) == pytest.approx(np.std(medians), rel=0.25)
    assert np.isnan(median_standard_error([1.0]))
