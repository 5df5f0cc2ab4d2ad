"""Paper 003's extended Kalman filter (eq. 2 re-linearised at the estimate) and the touchdown stop
in the filter: the compiled force law against eq. 2, the compiled loop's filter against a slow
numpy twin and against filterpy's ExtendedKalmanFilter, the debugger's replay against the loop,
and the exercise's choices."""

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter

from lab_modules.estimators.thrust_kalman import PAPER_Q_N2
from lab_modules.exercises import ANALYSIS
from lab_modules.exercises.thrust_liftoff import EXERCISE, setup
from lab_modules.loops.thrust_liftoff_loop import ThrustSetup, ThrustSimulation
from lab_modules.plants.thrust_bearing import MIN_MAGNETIC_GAP_M, PAPER_P0, TABLE_1, force_and_stiffness

T = TABLE_1.sample_time_s
M = TABLE_1.mass_kg
CLEARANCE = TABLE_1.touchdown_clearance_m
R = (5e-6) ** 2
#: Q_d = G_d Q G_dᵀ with G_d = (T²/2m, T/m) (eq. 11, 15): the same for both filters.
G_D = np.array([T * T / (2 * M), T / M])
Q_D = PAPER_Q_N2 * np.outer(G_D, G_D)


def slope_by_differences(x, i, h=1e-10):
    return (TABLE_1.magnetic_force_n(i, x + h) - TABLE_1.magnetic_force_n(i, x - h)) / (2 * h)


@pytest.mark.parametrize("x, i", [(0.0, 0.0), (2e-4, -1.5), (-3e-4, 4.0), (-0.7e-3, 0.3), (-0.75e-3, 2.0),
                                  (0.74e-3, -9.0)])
def test_compiled_force_law_is_eq_2_and_its_slope(x, i):
    force, slope = force_and_stiffness(x, i, TABLE_1.force_constants())
    assert force == pytest.approx(float(TABLE_1.magnetic_force_n(i, x)), rel=1e-12)
    assert slope == pytest.approx(float(slope_by_differences(x, i)), rel=1e-5)


def test_slope_at_the_centre_is_table_1s_stiffness():
    _, slope = force_and_stiffness(0.0, 0.0, TABLE_1.force_constants())
    assert slope == pytest.approx(TABLE_1.negative_stiffness_n_per_m, rel=1e-12)


def test_a_clipped_gap_adds_no_slope():
    """On the lower stop the lower gap is under the smallest gap: only the upper magnet's slope is left."""
    x = -CLEARANCE
    assert TABLE_1.gap_m + x < MIN_MAGNETIC_GAP_M
    i0, k_f, x0 = TABLE_1.bias_current_a, TABLE_1.force_constant_n_m2_per_a2, TABLE_1.gap_m
    _, slope = force_and_stiffness(x, 0.5, TABLE_1.force_constants())
    assert slope == pytest.approx(2 * k_f * (i0 + 0.5) ** 2 / (x0 - x) ** 3, rel=1e-12)


def twin_prediction(x_hat, P, i, knows_stop):
    """The EKF's prediction written out: eq. 2 by ``magnetic_force_n``, its slope by central
    differences, the second-order Taylor step and Φ_k = I + A_k T + (A_k T)²/2, then the stop."""
    a = float(TABLE_1.magnetic_force_n(i, x_hat[0])) / M
    a_x = float(slope_by_differences(x_hat[0], i)) / M
    A_k = np.array([[0.0, 1.0], [a_x, 0.0]])
    Phi = np.eye(2) + A_k * T + (A_k * T) @ (A_k * T) / 2
    x_new = np.array([x_hat[0] + T * x_hat[1] + T * T / 2 * a, x_hat[1] + T * a + T * T / 2 * a_x * x_hat[1]])
    if knows_stop and x_new[0] <= -CLEARANCE:
        x_new = np.array([-CLEARANCE, max(x_new[1], 0.0)])
    return x_new, Phi @ P @ Phi.T + Q_D


def loop_run(knows_stop, duration_s=0.08, seed=4):
    """The compiled loop with the EKF on the nonlinear plant, estimate fed back, sensor noise on."""
    setup_ = ThrustSetup(nonlinear=True, use_estimate=True, filter_extended=True, filter_knows_stop=knows_stop)
    sim = ThrustSimulation(setup_, seed=seed)
    return sim, sim.run(duration_s)


@pytest.mark.parametrize("knows_stop", [False, True])
def test_compiled_ekf_matches_the_slow_twin(knows_stop):
    """Fed the loop's own measurements z_k and coil currents i_k, the twin gives the loop's
    corrected estimate and σ_x sample by sample, through the lift-off (the force law's slope
    changes 20-fold) and at the stop."""
    _, trace = loop_run(knows_stop)
    x_hat, P = np.array([-0.75e-3, 0.0]), PAPER_P0.copy()
    H = np.array([1.0, 0.0])
    for k in range(trace["time_s"].size):
        S = H @ P @ H + R
        K = P @ H / S
        x_hat = x_hat + K * (trace["x_measured_m"][k] - x_hat[0])
        I_KH = np.eye(2) - np.outer(K, H)
        P = I_KH @ P @ I_KH.T + R * np.outer(K, K)
        assert x_hat[0] == pytest.approx(trace["x_estimated_m"][k], rel=1e-7, abs=1e-12), k
        assert x_hat[1] == pytest.approx(trace["velocity_estimated_m_per_s"][k], rel=1e-6, abs=1e-9), k
        assert np.sqrt(P[0, 0]) == pytest.approx(trace["x_sigma_m"][k], rel=1e-6), k
        x_hat, P = twin_prediction(x_hat, P, trace["current_a"][k], knows_stop)


class TaylorEKF(ExtendedKalmanFilter):
    """filterpy's EKF with the prediction of eq. 2's Taylor step (filterpy predicts x = F x + B u)."""

    def predict_x(self, u=0):
        i = float(u)
        x, v = self.x[0, 0], self.x[1, 0]
        a = float(TABLE_1.magnetic_force_n(i, x)) / M
        a_x = float(slope_by_differences(x, i)) / M
        self.x = np.array([[x + T * v + T * T / 2 * a], [v + T * a + T * T / 2 * a_x * v]])


def test_compiled_ekf_matches_filterpys_extended_kalman_filter():
    """filterpy's ExtendedKalmanFilter, given each sample's Jacobian Φ_k as F, tracks the loop's
    EKF (no stop) over a lift-off."""
    _, trace = loop_run(False, duration_s=0.05)
    ref = TaylorEKF(dim_x=2, dim_z=1)
    ref.x, ref.P, ref.R, ref.Q = np.array([[-0.75e-3], [0.0]]), PAPER_P0.copy(), np.array([[R]]), Q_D.copy()
    for k in range(trace["time_s"].size):
        ref.update(np.array([[trace["x_measured_m"][k]]]), lambda x: np.array([[1.0, 0.0]]), lambda x: x[:1])
        assert ref.x[0, 0] == pytest.approx(trace["x_estimated_m"][k], rel=1e-7, abs=1e-12), k
        assert np.sqrt(ref.P[0, 0]) == pytest.approx(trace["x_sigma_m"][k], rel=1e-6), k
        i = trace["current_a"][k]
        a_x = float(slope_by_differences(ref.x[0, 0], i)) / M
        A_k = np.array([[0.0, 1.0], [a_x, 0.0]])
        ref.F = np.eye(2) + A_k * T + (A_k * T) @ (A_k * T) / 2
        ref.predict(u=i)


@pytest.mark.parametrize("extended, knows_stop", [(True, False), (True, True), (False, True)])
def test_debugger_replay_equals_the_loops_filter(extended, knows_stop):
    setup_ = ThrustSetup(nonlinear=True, use_estimate=True, filter_extended=extended, filter_knows_stop=knows_stop)
    sim = ThrustSimulation(setup_, seed=2)
    trace = sim.run(0.06)
    history = sim.filter_tape().history()
    assert np.allclose(history.x_post[:, 0], trace["x_estimated_m"], rtol=1e-9, atol=1e-14)
    assert np.allclose(np.sqrt(history.P_post[:, 0, 0]), trace["x_sigma_m"], rtol=1e-9)
    if extended:                               # each sample's Jacobian, not one Φ
        assert np.ptp(history.Phi[:, 1, 0]) > 0.5 * np.max(np.abs(history.Phi[:, 1, 0]))


def test_the_stop_keeps_the_prediction_on_the_stop():
    """A collar held on the stop: the filter that knows the stop never predicts beyond it."""
    sim, _ = loop_run(True, duration_s=0.01)
    history = sim.filter_tape().history()
    assert np.min(history.x_prior[:, 0]) >= -CLEARANCE
    assert np.min(loop_run(False, duration_s=0.01)[0].filter_tape().history().x_prior[:, 0]) < -CLEARANCE


def test_filter_model_controls_choose_the_filter():
    values = EXERCISE.resolve({"filter_model": "EKF (eq. 2 re-linearised)", "filter_stop": "yes"})
    s = setup(values)
    assert s.filter_extended and s.filter_knows_stop and not s.filter_exact_model
    assert not setup(EXERCISE.resolve({})).filter_extended
    sim = EXERCISE.simulation(values)
    assert "Extended" in sim.filter_title and "stop" in sim.filter_title


def test_analysis_tab_shows_the_four_filters_on_the_nonlinear_plant():
    analysis = EXERCISE.analyse_panel(EXERCISE.resolve({}), ANALYSIS)
    plot = next(p for p in analysis.plots if p.title.startswith("Filters on the nonlinear plant"))
    assert len(plot.series) == 4
    peaks = {label: value for label, value, _ in analysis.readouts}
    linear = next(v for k, v in peaks.items() if k.endswith("linear (eq. 9-11)"))
    ekf_stop = next(v for k, v in peaks.items() if k.endswith("EKF + stop"))
    assert linear > 100 * ekf_stop
