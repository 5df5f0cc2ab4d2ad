"""LQG regulator of paper 000, §IV (lab_modules.controllers, analysis) against
scipy and python-control, and the exercise ``lqg_vs_pid`` against the paper's
claims (Figs. 7-9)."""

import control
import numpy as np
import pytest
import scipy.linalg
from scipy.optimize import linear_sum_assignment

from lab_modules import analysis
from lab_modules.amb_axis import RIG
from lab_modules.controllers import PAPER_LQG, PAPER_LQR_WEIGHTS, StateFeedback, integral_augmented_model, lqr

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
    loop = analysis.closed_loop(model, PAPER_LQG.integrator(), Kf, True, PAPER_LQG.gain_on(n))
    A, B = integral_augmented_model()
    regulator = control.ss(A - B @ gain_vector(PAPER_LQG)[None], B, np.eye(4), 0, T).poles()
    Ad, C = np.asarray(model.A), np.asarray(model.C)
    filter_poles = np.linalg.eigvals(Ad - Ad @ Kf @ C)
    expected = np.concatenate([regulator, filter_poles] + ([[np.exp(-T / sensor_lag_s)]] if n == 4 else []))
    assert pole_distance(analysis.loop_poles(loop), expected) <= 1e-6
