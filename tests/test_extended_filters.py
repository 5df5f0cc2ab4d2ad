"""The extended Kalman filters of §III against independent references:
eq. 10's derivatives by finite differences, e^{FT} by scipy, the filter steps
by filterpy's ExtendedKalmanFilter, and consistency (NEES, NIS) on a plant
that matches the filter's model."""

import control
import numpy as np
import pytest
import scipy.linalg
from filterpy.kalman import ExtendedKalmanFilter
from scipy.stats import chi2

from lab_modules.estimators import extended_kalman as ef
from lab_modules.plants.radial_bearing import DEFAULT_SENSOR_LAG_S, RIG

T = RIG.sample_time_s
PHYSICS = ef.physics_vector(RIG, DEFAULT_SENSOR_LAG_S)


@pytest.mark.parametrize("x_um, i_a", [(0.0, 0.0), (120.0, -1.5), (-200.0, 2.5)])
def test_local_factors_are_the_derivatives_of_eq_10(x_um, i_a):
    x = x_um * 1e-6
    kx, ki = ef.local_factors(x, i_a, PHYSICS)
    assert (kx, ki) == pytest.approx(RIG.local_factors(x, i_a), rel=1e-12)
    dx, di = 1e-9, 1e-5
    assert kx == pytest.approx((RIG.magnetic_force(x + dx, i_a) - RIG.magnetic_force(x - dx, i_a)) / (2 * dx),
                               rel=1e-6)
    assert ki == pytest.approx((RIG.magnetic_force(x, i_a + di) - RIG.magnetic_force(x, i_a - di)) / (2 * di),
                               rel=1e-6)


@pytest.mark.parametrize("model, state", [
    (ef.LINEARISED, np.array([30e-6, 0.01, 1.2, 120.0, 7.5e5])),
    (ef.NONLINEAR, np.array([80e-6, -0.02, -1.0, 70e-6, 150.0]))])
def test_jacobian_matches_finite_differences(model, state):
    F = np.zeros((5, 5))
    ef.jacobian(model, state, PHYSICS, F)
    steps = np.maximum(np.abs(state), [1e-6, 1e-3, 1e-2, 1e-6, 1.0]) * 1e-6
    numeric = np.zeros((5, 5))
    for j in range(5):
        up, down, f_up, f_down = state.copy(), state.copy(), np.zeros(5), np.zeros(5)
        up[j] += steps[j]
        down[j] -= steps[j]
        ef.derivative(model, up, 0.3, PHYSICS, f_up)
        ef.derivative(model, down, 0.3, PHYSICS, f_down)
        numeric[:, j] = (f_up - f_down) / (2 * steps[j])
    scale = np.abs(F).max(axis=1, keepdims=True) + 1e-300
    assert np.abs(F - numeric).max() == pytest.approx(0.0, abs=1e-9 * scale.max())
    assert np.all(np.abs(F - numeric) <= 1e-6 * scale)


def test_phi_is_the_truncated_exponential_and_eq_18_returns_the_factors():
    state = np.array([-100e-6, 0.0, 1.5, -100e-6, -200.0])
    F, Phi = np.zeros((5, 5)), np.zeros((5, 5))
    ef.jacobian(ef.NONLINEAR, state, PHYSICS, F)
    ef.transition_matrix(F, T, Phi)
    exact = scipy.linalg.expm(F * T)
    # the first neglected term of eq. 15 is F^3 T^3 / 6
    assert np.abs(Phi - exact).max() <= 1.01 * np.abs(np.linalg.matrix_power(F * T, 3)).max() / 6 + 1e-15
    kx, ki = ef.factors_from_phi(Phi, PHYSICS)
    assert (kx, ki) == pytest.approx(RIG.local_factors(state[0], state[2]), rel=1e-9)


def _filterpy_twin(filter_):
    """filterpy's EKF with the same model: Phi of eq. 15 as F, RK4 as predict_x."""
    twin = ExtendedKalmanFilter(5, 2)
    twin.x, twin.P = filter_.x.copy(), filter_.P.copy()
    twin.Q, twin.R = filter_.Q.copy(), filter_.R
    work = np.zeros((6, 5, 5))

    def predict_x(u):
        ef.rk4_step(filter_.model, twin.x, float(u), filter_.physics, work[0])
    twin.predict_x = predict_x
    return twin


@pytest.mark.parametrize("kind", ["parameters", "disturbance"])
def test_filters_equal_filterpy_extended_kalman_filter(kind):
    rng = np.random.default_rng(4)
    if kind == "parameters":
        f = ef.ParameterEKF([2e-6, 0.0, 0.2, 110.0, 7e5], np.diag([1e-10, 1e-6, 0.1, 40.0**2, 2e5**2]),
                            Q=np.diag([0, 2.6e-10, 1e-3, 1e-4, 1e2]))
    else:
        f = ef.DisturbanceEKF([2e-6, 0.0, 0.2, 0.0, 50.0], np.diag([1e-10, 1e-6, 0.1, 1e-10, 1e4]))
    twin = _filterpy_twin(f)
    F, Phi = np.zeros((5, 5)), np.zeros((5, 5))
    for _ in range(300):
        u = -0.3 * f.x[0] / 20e-6 + 0.2 * rng.standard_normal()
        ef.jacobian(f.model, twin.x, f.physics, F)
        ef.transition_matrix(F, T, Phi)
        twin.F = Phi.copy()
        twin.predict(u)
        f.predict(u)
        y = f.C @ f.x + np.sqrt(ef.PAPER_R_DIAG) * rng.standard_normal(2)
        twin.update(y, lambda x: f.C, lambda x: f.C @ x)
        f.update(y)
    sigma = np.sqrt(np.diag(twin.P))
    assert np.abs(f.x - twin.x).max() <= 1e-9 * np.abs(twin.x).max() + 1e-12 * sigma.max()
    assert np.all(np.abs(f.x - twin.x) <= 1e-9 * sigma)
    assert np.all(np.abs(f.P - twin.P) <= 1e-9 * np.outer(sigma, sigma))
    assert np.array_equal(f.P, f.P.T)
    assert np.linalg.eigvalsh(f.P / np.outer(sigma, sigma)).min() > 0


def _monte_carlo_nees_nis(filter_class, mean0, P0, q_diag, dither_v, seed, runs=25, steps=300):
    """Mean NEES and NIS of ``filter_class`` on a plant that *is* its model
    (eq. 9 or eq. 14) driven by the filter's own Q and R, under a stabilising
    LQR (python-control) on the estimate plus a known random input of
    ``dither_v``; the first 50 samples of each run are skipped."""
    rng = np.random.default_rng(seed)
    A, B = (np.asarray(M) for M in (RIG.discrete_model().A, RIG.discrete_model().B))
    gain, _, _ = control.dlqr(A, B[:, :1], np.diag([1e10, 1e2, 1.0]), np.array([[1.0]]))
    nees, nis = [], []
    work = np.zeros((6, 5, 5))
    for _ in range(runs):
        truth = mean0 + rng.multivariate_normal(np.zeros(5), P0)
        f = filter_class(mean0, P0, Q=np.diag(q_diag))
        for k in range(steps):
            f.update(f.C @ truth + np.sqrt(f.R_diag) * rng.standard_normal(2))
            if k >= 50:
                error = truth - f.x
                nees.append(error @ np.linalg.solve(f.P, error))
                nis.append(f.nis)
            u = float(-gain[0] @ f.x[:3]) + dither_v * rng.standard_normal()
            f.predict(u)
            ef.rk4_step(f.model, truth, u, f.physics, work[0])
            truth += np.sqrt(q_diag) * rng.standard_normal(5)
    return np.mean(nees), np.mean(nis), len(nees)


def chi2_bounds(dof, n):
    """Two-sided 99 % bounds of the mean of n chi-square(dof) values."""
    return chi2.ppf([0.005, 0.995], dof * n) / n


def test_disturbance_filter_is_consistent_on_a_matched_plant():
    """§III-B: NEES (5 states) and NIS (2 measurements) inside their bounds."""
    q_diag = np.array([0.0, (2.0 * T / RIG.equivalent_mass_kg) ** 2, 1e-4, 0.0, 4.0])
    P0 = np.diag([2e-6, 2e-3, 0.05, 1e-7, 30.0]) ** 2
    nees, nis, n = _monte_carlo_nees_nis(ef.DisturbanceEKF, np.zeros(5), P0, q_diag, 0.0, seed=11)
    assert chi2_bounds(5, n)[0] <= nees <= chi2_bounds(5, n)[1]
    assert chi2_bounds(2, n)[0] <= nis <= chi2_bounds(2, n)[1]


def test_parameter_filter_is_not_overconfident_on_a_matched_plant():
    """§III-A: the bilinear terms k_x x and k_i i make the EKF's P only
    approximate; it errs on the cautious side (mean NEES about 4.7 of 5), so
    the NEES is held to the upper bound only; the NIS to both."""
    q_diag = np.array([0.0, (2.0 * T / RIG.equivalent_mass_kg) ** 2, 1e-4, 1e-4, 1e2])
    mean0 = np.array([0.0, 0.0, 0.0, RIG.ki_n_per_a, RIG.kx_n_per_m])
    P0 = np.diag([2e-6, 2e-3, 0.05, 5.0, 3e4]) ** 2
    nees, nis, n = _monte_carlo_nees_nis(ef.ParameterEKF, mean0, P0, q_diag, 0.3, seed=12)
    assert nees <= chi2_bounds(5, n)[1]
    assert chi2_bounds(2, n)[0] <= nis <= chi2_bounds(2, n)[1]


def test_disturbance_filter_rejects_a_missing_sensor_lag():
    with pytest.raises(ValueError, match="T_mx"):
        ef.DisturbanceEKF(np.zeros(5), np.eye(5), sensor_lag_s=0.0)
