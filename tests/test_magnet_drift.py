"""adaptive_filter's magnet-drift run (paper 002, Figs. 1 and 8 online): the compiled loop against
a slow, obvious twin, the ADALINE on the filter's force balance, the consistency tests, the
25-node network and the scope's columns."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from lab_modules.estimators.fuzzy_basis_network import CENTRES, evaluate
from lab_modules.estimators.scheduled_kalman import model_matrices, predict_exact_force, process_noise
from lab_modules.exercises import _magnet_drift as drift
from lab_modules.exercises.adaptive_filter import EXERCISE, drift_results, setup
from lab_modules.loops.magnet_drift_loop import COLUMN, COLUMNS, FILTERS, DriftSimulation
from lab_modules.plants.axial_bearing import force_shape, magnet_force

VALUES = EXERCISE.resolve({})


def _slow_twin(simulation: DriftSimulation, noise: np.ndarray) -> np.ndarray:
    """The drift loop written out sample by sample in plain Python (module docstring of
    ``loops.magnet_drift_loop``), on a copy of the simulation's state."""
    setup_, physics, pid, net = simulation.setup, simulation.physics, simulation.pid, simulation.networks
    loop = setup_.loop
    m, T, lag, gain, g = physics[0], physics[1], physics[2], physics[3], physics[4]
    R, k0, gap, bias = physics[7], physics[8], physics[9], physics[10]
    x = v = xm = integral = reference = 0.0
    k_hat = k0 * 1e6
    z = [np.zeros(4) for _ in FILTERS]
    P = [np.diag([20e-6, 1e-3, 1.0, 20e-3]) ** 2 for _ in FILTERS]
    rows = []
    for k in range(noise.shape[0]):
        t = k * T
        segment = [s for s in loop.segments if t >= s.start_s - 1e-12][-1]
        index = loop.segments.index(segment)
        load = segment.disturbance_n
        since = t - segment.start_s
        if index > 0 and since < loop.load_ramp_s:
            previous = loop.segments[index - 1].disturbance_n
            load = previous + (load - previous) * since / loop.load_ramp_s
        k_true = k0 * (1.0 + setup_.change if t >= setup_.start_s else 1.0)
        y = xm + noise[k, 0]
        truth = np.array([x, v, load])
        nis, nees = [], []
        for f in range(4):
            S = P[f][3, 3] + R
            nis.append((y - z[f][3]) ** 2 / S)
            K = P[f][:, 3] / S
            z[f] = z[f] + K * (y - z[f][3])
            IKH = np.eye(4) - np.outer(K, [0, 0, 0, 1.0])
            P[f] = IKH @ P[f] @ IKH.T + R * np.outer(K, K)
            e = truth - z[f][:3]
            nees.append(e @ np.linalg.inv(P[f][:3, :3]) @ e)
        reference += (segment.reference_m - reference) * T / pid.reference_filter_s
        error = reference - z[2][0]
        integral += error * T
        command = pid.feedforward_a + pid.proportional_a_per_m * (error + integral / pid.integral_time_s) \
            - pid.derivative_a_s_per_m * z[2][1]
        if abs(command) > bias:
            command, integral = np.sign(command) * bias, integral - error * T
        current = float(np.clip(command + noise[k, 1], -bias, bias))
        ki_f = evaluate(command, z[2][0], CENTRES, net.ki_weights, net.ki_widths)
        ks_f = evaluate(command, z[2][0], CENTRES, net.ks_weights, net.ks_widths)
        target = k_hat / (k0 * 1e6) * (ki_f * command + ks_f * z[2][0]) + z[2][2] - load
        phi = force_shape(command, z[2][0], gap, bias) * 1e-6
        k_hat += net.adaline_rate * (target - k_hat * phi) * phi                         # eq. 24
        rows.append([t, x, load, k_hat, *[z[f][2] - load for f in range(4)], *nis, *nees])
        A, B, Q = np.zeros((4, 4)), np.zeros((4, 2)), np.zeros((4, 4))
        for f, (ki, ks) in enumerate([(4 * k0 * bias / gap**2, 4 * k0 * bias**2 / gap**3),
                                      (evaluate(command, z[1][0], CENTRES, net.ki_weights, net.ki_widths),
                                       evaluate(command, z[1][0], CENTRES, net.ks_weights, net.ks_widths)),
                                      (k_hat / (k0 * 1e6) * ki_f, k_hat / (k0 * 1e6) * ks_f)]):
            model_matrices(ki, ks, physics, A, B)
            process_noise(physics, B, Q)
            z[f] = A @ z[f] + B[:, 0] * command + B[:, 1]
            P[f] = A @ P[f] @ A.T + Q
        exact = physics.copy()
        exact[8] = k_true
        predict_exact_force(z[3], P[3], exact, command, A, B, Q)
        h = T / 2
        def rates(s, current=current, k_true=k_true, load=load):
            return np.array([s[1], (magnet_force(current, s[0], k_true, gap, bias) + load) / m - g,
                             (gain * s[0] - s[2]) / lag])
        for _ in range(2):
            s0 = np.array([x, v, xm])
            d1 = rates(s0)
            d2 = rates(s0 + h / 2 * d1)
            d3 = rates(s0 + h / 2 * d2)
            d4 = rates(s0 + h * d3)
            x, v, xm = s0 + h / 6 * (d1 + 2 * d2 + 2 * d3 + d4)
    return np.array(rows)


def test_compiled_loop_matches_its_slow_twin():
    """Through a move, a load ramp and a k_Magnet step at 30 ms: states, k̂, NIS and NEES agree."""
    drift_setup = replace(drift.drift_setup(VALUES, setup(VALUES)), start_s=0.03005)   # between samples: no rounding at the edge
    simulation = DriftSimulation(drift_setup, seed=4)
    n = 1200
    rng = np.random.default_rng(4)
    noise = np.column_stack([rng.normal(0, np.sqrt(drift_setup.loop.var_sensor_v2), n),
                             rng.normal(0, np.sqrt(drift_setup.loop.var_process_a2), n), np.zeros(n)])
    twin = _slow_twin(simulation, noise)
    fast = simulation.advance(n)                      # the same stream: seed 4, the same draws in order
    names = ["x_true_m", "disturbance_n", "k_magnet_estimate", *[f"{f}_force_error_n" for f in FILTERS],
             *[f"{f}_nis" for f in FILTERS], *[f"{f}_nees" for f in FILTERS]]
    compiled = np.column_stack([fast[:, 0]] + [fast[:, COLUMN[name]] for name in names])
    assert compiled == pytest.approx(twin, rel=1e-6, abs=1e-9)
    assert twin[-1, 3] < 6.7 * 0.97                   # k̂ has moved towards the stepped 6.03


@pytest.fixture(scope="module")
def results():
    return drift_results(dict(VALUES))


def test_adaline_finds_the_stepped_magnet_and_the_adaptive_bias_falls(results):
    t, k_estimate = results["t"], results["k_estimate"]
    late = (t > 0.35) & (t < 0.45)
    assert np.mean(k_estimate[late]) == pytest.approx(6.7 * 0.9, rel=0.01)
    assert results["time_to_10pct_ms"] < results["stated_ms"] * 1.25
    point1 = results["windows"]["point 1"]
    assert abs(point1["adaptive"]) < 0.1 * abs(point1["offline"]) and abs(point1["exact"]) < 0.05


def test_no_drift_leaves_the_offline_filter_unbiased_and_k_hat_near_nominal():
    found = drift_results({**VALUES, "k_magnet_change_pct": 0.0})
    assert abs(found["windows"]["point 1"]["offline"]) < 0.1
    assert np.mean(found["k_estimate"][-1000:]) == pytest.approx(6.7, rel=0.01)


def test_a_large_step_size_makes_the_identification_ring():
    """With η far above the stated limit the weight overshoots its target (the force state's lag)."""
    quick = drift_results(dict(VALUES))["k_estimate"]
    fast = drift_results({**VALUES, "adaline_rate": 0.012})["k_estimate"]
    window = slice(round(0.2 / 1e-4), round(0.26 / 1e-4))
    assert np.min(fast[window]) < 6.03 - 0.2 < np.min(quick[window])


def test_consistency_tests_say_which_way_a_filter_is_wrong(results):
    tests = results["consistency"]["point 1"]
    nees_fixed, nis_fixed = tests["fixed"]
    assert nees_fixed.verdict.startswith("overconfident") and nis_fixed.inside
    assert tests["exact"][1].inside and tests["adaptive"][1].inside


def test_nodes_alone_train_a_worse_map_than_the_bilinear_table():
    from lab_modules.exercises._stiffness_networks import NETWORK_DEFAULTS, map_test_rmse, networks
    grid = map_test_rmse(networks(NETWORK_DEFAULTS), NETWORK_DEFAULTS)
    nodes = map_test_rmse(networks({**NETWORK_DEFAULTS, "fbfnn_training": "25 nodes"}), NETWORK_DEFAULTS)
    assert grid["k_s"]["fbfnn"] < grid["k_s"]["bilinear"] < nodes["k_s"]["fbfnn"]


def test_scope_carries_the_drift_run_and_its_live_consistency():
    simulation = EXERCISE.simulation(dict(VALUES))
    trace = simulation.advance(600)
    named = {name: trace[:, 1 + j] for j, name in enumerate(simulation.columns)}
    assert all(f"drift_{name}" in named for name in COLUMNS)
    live = EXERCISE.live_readouts(named)
    assert sum(label.startswith("Drift: NIS") for label, _, _ in live) == len(FILTERS)
    assert all(np.isfinite(value) for _, value, _ in live)


def test_miso_identifier_is_worse_at_the_points_and_faster_after_the_step():
    """The SISO and MISO ADALINEs on the same drift runs and force sensor (``identifier_errors``):
    the MISO's local slopes must be learnt again at each point, its two weights follow the step
    faster; each RMS is the a-priori force error, so an identifier that learns nothing scores
    the step's whole force change."""
    found = drift_results(EXERCISE.resolve({}))["identifiers"]
    ratio = found["miso_over_siso"]
    assert ratio["point 1"] > 1.3 and ratio["point 2"] > 1.3 and ratio["the move"] > 1.5
    assert ratio["after the change"] < 1.0
    assert found["siso_rms_n"]["point 1"] < 0.15      # 10 % of k_Magnet at point 1 would be about 1.5 N
