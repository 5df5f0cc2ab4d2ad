"""Exercise ``self_sensing`` (paper 001): the reluctance model, the half-period
least squares against scipy, the averaging, the error propagation, the paper's
claims, and bad command-line input."""

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from lab_modules.estimators.ripple_inductance import fit, predicted_sigma_inductance_h, weights
from lab_modules.exercises._self_sensing_geometry import analysis as geometry_analysis
from lab_modules.exercises._self_sensing_geometry import straight_ramp_sigma_gap_m
from lab_modules.exercises._self_sensing_levitation import loop_control, spread_run
from lab_modules.exercises.self_sensing import (
    EXERCISE,
    LEVITATED,
    QUIET,
    SelfSensingSimulation,
    setup,
    stationary,
    statistics,
)
from lab_modules.loops.self_sensing_levitation import (
    linear_loop,
    predicted_gap_spread_m,
    spread_relative_error,
)
from lab_modules.loops.self_sensing_loop import (
    COLUMN,
    SelfSensingLoop,
    SelfSensingSetup,
    duty_for_mean_current,
)
from lab_modules.plants.self_sensing_ball import MU0, RIG

REPO = Path(__file__).resolve().parents[1]


# -- the plant (eq. 1-2) ---------------------------------------------------------------------------
def test_inductance_from_the_reluctance_network_by_hand():
    """L = N²/R with the core in series with (leakage ∥ (gap + ball)), written out independently."""
    for gap, expected_mh in ((4e-3, 31.466), (6e-3, 28.901)):
        core = 0.080 / (MU0 * 2000 * 2.0e-4)
        ball = 0.030 / (MU0 * 2000 * 3.0e-4)
        air = gap / (MU0 * 7.0e-5)
        total = core + 1.0 / (1.0 / 1.5e7 + 1.0 / (air + ball))
        assert 600**2 / total == pytest.approx(float(RIG.inductance_h(gap)), rel=1e-12)
        assert float(RIG.inductance_h(gap)) * 1e3 == pytest.approx(expected_mh, rel=1e-4)


def test_inverse_slope_sensitivity_and_equilibrium():
    gaps = np.linspace(2e-3, 8e-3, 13)
    L = RIG.inductance_h(gaps)
    assert np.allclose(RIG.gap_m(L), gaps, rtol=0, atol=1e-12)
    h = 1e-8
    slope = (RIG.inductance_h(gaps + h) - RIG.inductance_h(gaps - h)) / (2 * h)
    assert np.allclose(RIG.inductance_slope_h_per_m(gaps), slope, rtol=1e-6)
    assert np.allclose(RIG.position_sensitivity_m_per_h(L), 1 / np.abs(slope), rtol=1e-6)   # eq. 32 factor
    currents = RIG.equilibrium_current_a(np.array([4e-3, 6e-3]))
    assert currents == pytest.approx([1.196, 1.791], abs=2e-3)
    assert np.mean(currents) == pytest.approx(1.5, abs=0.01)             # the paper's ī
    force = 0.5 * currents**2 * np.abs(RIG.inductance_slope_h_per_m(np.array([4e-3, 6e-3])))
    assert force == pytest.approx(RIG.ball_mass_kg * 9.81, rel=1e-9)


# -- the half-period least squares (eq. 7-10, 28-30) against scipy ----------------------------------
def ramp(n=600, inductance=0.0315, voltage=11.4, resistance=2.5, i0=1.1, ts=1e-6, sigma=0.0, seed=0):
    """Samples of a coil current under constant voltage (exact exponential) plus noise."""
    t = np.arange(n + 1) * ts
    tau = inductance / resistance
    current = voltage / resistance + (i0 - voltage / resistance) * np.exp(-t / tau)
    noisy = current + sigma * np.random.default_rng(seed).standard_normal(n + 1)
    return noisy, np.full(n + 1, voltage), current


def test_fit_matches_scipy_linregress_including_standard_error():
    """θ̂ and σ̂(θ̂₂) of eq. 10 and 29 (with M − d) equal linregress's slope, intercept and stderr."""
    current, voltage, _ = ramp(sigma=1e-3)
    start, stop, r_hat, ts = 10, 590, 2.5, 1e-6
    flux = np.concatenate([[0.0], np.cumsum(voltage[start:stop] - r_hat * current[start:stop])])
    reference = stats.linregress(flux, current[start:stop + 1])
    result = fit(current, voltage, start, stop, r_hat, ts)
    slope = ts / result["inductance_h"]
    assert slope == pytest.approx(reference.slope, rel=1e-10)
    assert result["initial_current_a"] == pytest.approx(reference.intercept, rel=1e-10)
    sigma_slope = math.sqrt(result["variance_inductance_h2"]) * slope**2 / ts            # eq. 30 undone
    assert sigma_slope == pytest.approx(reference.stderr, rel=1e-8)
    printed = fit(current, voltage, start, stop, r_hat, ts, dof="M + d")                 # eq. 28 as printed
    m = stop - start + 1
    assert printed["variance_current_a2"] == pytest.approx(result["variance_current_a2"] * (m - 2) / (m + 2))


def test_noise_free_ramp_gives_the_inductance_and_the_straight_ramp_sigma():
    current, voltage, _ = ramp()
    result = fit(current, voltage, 8, 592, 2.5, 1e-6)
    assert result["inductance_h"] == pytest.approx(0.0315, rel=1e-4)   # forward Euler (eq. 7): 4e-5
    # σ(L̂) of a straight ramp with 1 mA noise, against many noisy fits
    estimates, predictions = [], []
    for seed in range(400):
        noisy, voltage, _ = ramp(sigma=1e-3, seed=seed)
        r = fit(noisy, voltage, 8, 592, 2.5, 1e-6)
        estimates.append(r["inductance_h"])
        predictions.append(math.sqrt(r["variance_inductance_h2"]))
    ramp_sigma = predicted_sigma_inductance_h(0.0315, 1e-3, 11.4 - 2.5 * 1.3, 585, 1e-6)
    assert np.mean(predictions) == pytest.approx(ramp_sigma, rel=0.05)
    assert np.std(estimates) == pytest.approx(np.mean(predictions), rel=0.1)


def test_weights_add_up_to_one_and_favour_the_steeper_phase():
    w1, w2 = weights((0.168, -0.165), (1.196, 1.196), (630e-6, 360e-6))
    assert w1 + w2 == pytest.approx(1.0)
    assert w2 > w1                                    # the shorter, steeper phase II weighs more


# -- half-period estimates one by one (eq. 7 with − R̂ i; eq. 11-17) ---------------------------------
def rows_at(gap_m=4e-3, **changes):
    loop = SelfSensingLoop(SelfSensingSetup(trajectory="fixed at gap 1", gap_1_m=gap_m, **changes))
    loop.run(30)
    return loop.run(50)[0]


def test_half_period_estimates_are_each_right_with_the_fixed_eq_7():
    rows = rows_at()
    truth = rows[:, COLUMN["inductance_true_h"]]
    for column in ("inductance_1_h", "inductance_2_h", "inductance_mean_h"):
        assert np.max(np.abs(rows[:, COLUMN[column]] / truth - 1)) < 2e-4, column


def test_printed_eq_7_spoils_each_half_period_but_not_the_average():
    rows = rows_at(printed_eq7=True)
    truth = rows[:, COLUMN["inductance_true_h"]]
    assert np.mean(rows[:, COLUMN["inductance_1_h"]] / truth - 1) > 0.5
    assert np.mean(rows[:, COLUMN["inductance_2_h"]] / truth - 1) < -0.3
    assert abs(np.mean(rows[:, COLUMN["inductance_mean_h"]] / truth - 1)) < 2e-4


def test_resistance_error_follows_eq_17_with_opposite_signs():
    """L̂ = L + ΔR ī Δt/Δi per phase (eq. 17 at rest) with R̂ = 0.8 R; the average removes it."""
    rows = rows_at(resistance_ratio=0.8)
    truth = rows[:, COLUMN["inductance_true_h"]]
    delta_r = 0.2 * RIG.coil_resistance_ohm
    for phase, target in (("1", 7.12), ("2", -4.15)):
        error = rows[:, COLUMN[f"inductance_{phase}_h"]] - truth
        window = (rows[:, COLUMN["duty"]] * 1024 - 16 if phase == "1" else (1 - rows[:, COLUMN["duty"]]) * 1024 - 16)
        eq_17 = delta_r * rows[:, COLUMN[f"mean_current_{phase}_a"]] * window * 1e-6 / rows[:, COLUMN[f"delta_current_{phase}_a"]]
        assert np.allclose(error, eq_17, rtol=0.01)
        assert np.mean(error / truth) * 100 == pytest.approx(target, abs=0.3)
    assert np.max(np.abs(rows[:, COLUMN["inductance_mean_h"]] / truth - 1)) < 2e-4


def test_gain_errors_scale_the_average_by_eta_over_mu():
    for mu, eta in ((1.05, 1.0), (1.0, 1.05), (1.03, 0.98)):
        rows = rows_at(current_gain=mu, voltage_gain=eta)
        ratio = rows[:, COLUMN["inductance_mean_h"]] / rows[:, COLUMN["inductance_true_h"]]
        assert np.mean(ratio) == pytest.approx(mu / eta, abs=1e-4)     # eq. 22: L̄_m = (μ/η) L̄


# -- the exercise ------------------------------------------------------------------------------------
def test_simulation_rows_are_per_period_not_raw_samples():
    values = EXERCISE.resolve({})
    simulation = EXERCISE.simulation(values)
    assert simulation.sample_time_s == pytest.approx(1.024e-3)
    rows = simulation.advance(20)
    assert rows.shape == (20, 1 + len(SelfSensingSimulation.columns))


def test_retune_carries_the_run_on():
    values = EXERCISE.resolve({})
    simulation = EXERCISE.simulation(values)
    first = simulation.advance(30)
    retuned = EXERCISE.retune(simulation, {**values, "resistance_ratio": 0.8})
    second = retuned.advance(5)
    assert second[0, 0] == pytest.approx(first[-1, 0] + simulation.sample_time_s)
    assert abs(second[0, 1 + COLUMN["current_mean_true_a"]] - first[-1, 1 + COLUMN["current_mean_true_a"]]) < 0.01


def test_trim_is_a_share_of_the_period():
    assert setup(EXERCISE.resolve({})).trim_samples == 8
    assert setup(EXERCISE.resolve({"sample_time_us": "0.5"})).trim_samples == 16
    assert setup(EXERCISE.resolve({"sample_time_us": "0.5", "pwm_mode": "T_pwm = 1024 T_a"})).trim_samples == 8


def test_stationary_noise_free_position_error_below_5_um():
    values = EXERCISE.resolve(QUIET)
    for gap in ("gap_1", "gap_2"):
        assert statistics(stationary(values, gap))["position_error_max_um"] < 5.0


# -- the paper's claims ------------------------------------------------------------------------------
_METRICS: dict[str, dict] = {}


def metrics_for(claim) -> dict:
    key = json.dumps(claim.settings, sort_keys=True) + str(claim.duration_s)
    if key not in _METRICS:
        values = EXERCISE.resolve(claim.settings)
        _METRICS[key] = EXERCISE.metrics(values, claim.duration_s or EXERCISE.default_duration_s)
    return _METRICS[key]


@pytest.mark.parametrize("claim", EXERCISE.claims, ids=lambda c: c.quantity)
def test_claim(claim):
    value = claim.value_in(metrics_for(claim))
    assert claim.holds(value), f"{claim.quantity}: {value:g} {claim.unit} not in {claim.accept_text()}"


# -- command line ------------------------------------------------------------------------------------
def run_app(*argv):
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return subprocess.run([sys.executable, "-m", "app", *argv], check=False, cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("setting, named", [
    ("sigma_current_ma=abc", "0 ... 20 mA"),
    ("sample_time_us=3", "0.5, 1, 2"),
    ("gap_1_mm=nan", "2 ... 8 mm"),
    ("trim_samples=2.5", "0 ... 100 samples"),
])
def test_bad_input_exits_2_with_one_line(setting, named):
    result = run_app("run", "self_sensing", "--set", setting, "--json")
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and setting.split("=")[0] in lines[0] and named in lines[0]


def test_headless_run_json_has_the_metrics():
    result = run_app("run", "self_sensing", "--duration", "0.3", "--json")
    assert result.returncode == 0, result.stderr
    metrics = json.loads(result.stdout)["metrics"]
    for key in ("inductance_mh", "predicted_sigma_half_period_uh", "predicted_sigma_inductance_uh",
                "predicted_sigma_position_um", "monte_carlo_to_predicted_ratio", "within_3sigma_percent",
                "position_bias_um", "realtime_factor"):
        assert key in metrics
    assert set(metrics["predicted_sigma_half_period_uh"]["gap_1"]) == {"phase_1", "phase_2"}
    assert metrics["realtime_factor"] > 0


# -- geometry, Fig. 2's gains, eq. 25 during the moves ------------------------------------------------
def test_geometry_controls_default_to_the_lab_rig_and_reach_the_loop():
    assert setup(EXERCISE.resolve({})).rig == RIG
    s = setup(EXERCISE.resolve({"turns": 900, "gap_area_cm2": 0.35, "leakage_reluctance": 6e7}))
    assert (s.rig.turns, s.rig.gap_area_m2, s.rig.leakage_reluctance_per_h) == (900, pytest.approx(35e-6), 6e7)
    rows = SelfSensingSimulation(EXERCISE.resolve({**QUIET, "turns": 900})).advance(5)
    assert rows[-1, 1 + COLUMN["inductance_true_h"]] == pytest.approx(float(RIG.inductance_h(4e-3)) * 1.5**2,
                                                                       rel=1e-3)     # L = N²/R (eq. 2)


def test_straight_ramp_sigma_follows_the_simulation_across_geometries():
    for change in ({}, {"turns": 450}, {"leakage_reluctance": 3e7}):
        values = EXERCISE.resolve(change)
        s = setup(values)
        simulated = statistics(stationary(values, "gap_1", periods=1500))["predicted_sigma_position_um"]
        assert simulated == pytest.approx(straight_ramp_sigma_gap_m(s.rig, s.gap_1_m, s) * 1e6, rel=0.03)


def test_trade_off_plots_show_slower_coil_with_turns_and_less_spread_with_less_leakage():
    plots = {p.title.split(":")[1].strip()[:6]: p for p in geometry_analysis(setup(EXERCISE.resolve({})))[2]}
    sigma = {label.split(" ")[0]: y for label, y, _ in plots["σ(ŝ) w"].series}
    tau = {label.split(" ")[0]: y for label, y, _ in plots["coil t"].series}
    assert np.all(np.diff(tau["N"]) > 0) and np.all(np.diff(sigma["N"]) > 0)      # L ∝ N², σ(ŝ) ∝ N²
    assert np.all(np.diff(sigma["R_l"]) < 0) and np.all(np.diff(tau["R_l"]) < 0)  # leakage costs both


def test_scope_gains_read_mu_and_one_over_eta_as_fig_2():
    for change, mu_hat in (({"current_gain": 1.05}, 1.05), ({"voltage_gain": 1.05}, 1 / 1.05)):
        values = EXERCISE.resolve({**QUIET, **change})
        rows = SelfSensingSimulation(values).advance(30)
        columns = ("t",) + SelfSensingSimulation.columns
        ratio = rows[5:, columns.index("inductance_ratio")]
        assert np.mean(ratio) == pytest.approx(mu_hat, abs=2e-4)
        assert np.mean(rows[5:, columns.index("voltage_gain_estimate")]) == pytest.approx(1 / mu_hat, abs=2e-4)
        assert rows[-1, columns.index("gain_ratio_set")] == pytest.approx(mu_hat)


def test_offset_shift_during_moves_follows_eq_25_and_vanishes_without_offset():
    metrics = EXERCISE.metrics(EXERCISE.resolve({**QUIET, "voltage_offset_v": 0.57}), 1.3)["trajectory"]["offset"]
    assert metrics["shift_to_eq25"] == pytest.approx(1.0, abs=0.05)
    assert metrics["shift_max_uh"] > metrics["shift_at_rest_max_uh"]          # the moves make īᴵᴵ ≠ īᴵ
    assert "offset" not in EXERCISE.metrics(EXERCISE.resolve(QUIET), 0.3)["trajectory"]


# -- levitation on ŝ: the linear loop's predictions ----------------------------------------------------
def levitated_values(**overrides) -> dict:
    return EXERCISE.resolve({**LEVITATED, **overrides})


def test_spread_and_its_statistical_error_match_a_monte_carlo_of_the_linear_loop():
    values = levitated_values()
    s = setup(values)
    loop = linear_loop(s, loop_control(values), s.gap_1_m)
    sigma, n_periods, runs, burn_in = 10e-6, 4000, 400, 600
    rng = np.random.default_rng(3)
    state = np.zeros((7, runs))
    gaps = np.empty((n_periods, runs))
    for k in range(burn_in + n_periods):
        state = loop.closed @ state + np.outer(loop.noise_input, sigma * rng.standard_normal(runs))
        if k >= burn_in:
            gaps[k - burn_in] = state[0]
    ratios = gaps.std(axis=0) / predicted_gap_spread_m(loop, sigma)
    assert abs(ratios.mean() - 1.0) < 0.01                          # Lyapunov: mean std, ±0.2 % sampling
    assert ratios.std() / spread_relative_error(loop, n_periods) == pytest.approx(1.0, abs=0.15)   # Bartlett


def test_duty_and_gap_spread_follow_the_linear_loop_while_the_duty_stays_clear_of_its_limits():
    values = levitated_values(sigma_current_ma=0.5, sigma_voltage_mv=7.5)
    s, control_ = setup(values), loop_control(values)
    run = spread_run(s, control_, linear_loop(s, control_, s.gap_1_m), 0, 5.0)
    assert run["duty_at_limit_percent"] == 0.0
    assert run["duty_std_to_predicted"] == pytest.approx(1.0, abs=0.03)
    assert run["gap_std_to_predicted"] == pytest.approx(1.0, abs=0.12)   # one run's std: ±3.9 %


def test_duty_rule_linearised_by_the_loop_matches_its_own_finite_step():
    values = levitated_values()
    s, control_ = setup(values), loop_control(values)
    loop = linear_loop(s, control_, s.gap_1_m)
    current = float(RIG.equilibrium_current_a(s.gap_1_m))
    inductance_h = float(RIG.inductance_h(s.gap_1_m))
    step = 0.02                                                     # a 20 mA command step, the start held

    def duty(target_a: float) -> float:
        return duty_for_mean_current(current, inductance_h, target_a, inductance_h, RIG.coil_resistance_ohm,
                                     s.battery_voltage_v, s.period_s)
    state = np.zeros(7)
    state[3] = step                                                 # the integral term alone moves i* by 20 mA
    assert duty(current + step) - duty(current) == pytest.approx(loop.duty_row @ state, rel=1e-3)
    state[3], state[6] = 0.0, step                                  # the period starts 20 mA higher
    assert duty_for_mean_current(current + step, inductance_h, current, inductance_h, RIG.coil_resistance_ohm,
                                 s.battery_voltage_v, s.period_s) - duty(current) == pytest.approx(
        loop.duty_row @ state, rel=1e-3)
