"""The linear Kalman filter of eq. 2 (lab_modules.estimators) and its use in
the compiled closed loop (lab_modules.loops.radial_axis_experiment).

Covariances hold entries from ~1e-14 m^2 to ~1 A^2, so they are compared
entry by entry relative to sqrt(P_ii P_jj) (the scale of that entry), not
relative to the largest entry, which would hide errors in the position block.
"""

import numpy as np
import pytest
import scipy.linalg
import scipy.stats
from filterpy.kalman import KalmanFilter as FilterpyKalmanFilter

from lab_modules import analysis
from lab_modules.estimators.kalman import KalmanFilter
from lab_modules.exercises.kalman_noise import EXERCISE, setup
from lab_modules.loops import radial_axis_loop
from lab_modules.loops.radial_axis_experiment import AxisSimulation
from lab_modules.plants.radial_bearing import RIG

LAGS_S = [0.0, 200e-6]
T = RIG.sample_time_s


def scaled_difference(P, P_ref):
    """max |P - P_ref|_ij / sqrt(P_ref,ii P_ref,jj)."""
    d = np.sqrt(np.diag(P_ref))
    return np.max(np.abs(P - P_ref) / np.outer(d, d))


def dare_covariance(A, C, Q, R):
    """A-priori steady-state covariance of eq. 2 from scipy's DARE (dual of the LQR one)."""
    return scipy.linalg.solve_discrete_are(A.T, C.T, Q, R)


def kalman_noise_setup(**changes):
    """The kalman_noise exercise's default set-up, with ``changes`` applied."""
    return setup(EXERCISE.resolve({})).with_changes(**changes)


def model_matrices(axis):
    return np.asarray(axis.model.A), np.asarray(axis.model.B), np.asarray(axis.model.C)


# -- eq. 2 step by step, against filterpy ---------------------------------------

@pytest.mark.parametrize("sensor_lag_s", LAGS_S)
def test_filter_matches_filterpy_step_by_step(sensor_lag_s):
    """500 predict/update steps on the bearing model with random u and y: states
    (norm-relative and in units of their sigma) and covariances equal filterpy's
    within 1e-9 relative after every step."""
    axis = kalman_noise_setup(sensor_lag_s=sensor_lag_s)
    A, B, C = model_matrices(axis)
    Q, R = axis.filter_Q, axis.filter_R
    n = A.shape[0]
    rng = np.random.default_rng(12345)
    x0 = rng.normal(0, 1, n) * np.array([10e-6, 1e-3, 0.1, 10e-6])[:n]
    P0 = np.diag([(10e-6) ** 2, (1e-3) ** 2, 0.1**2, (10e-6) ** 2][:n])

    ours = KalmanFilter(A, B[:, 0], C, Q, np.diag(R), x0, P0)
    ref = FilterpyKalmanFilter(dim_x=n, dim_z=2, dim_u=1)
    ref.F, ref.B, ref.H, ref.Q, ref.R = A, B[:, :1], C, Q, R
    ref.x, ref.P = x0.reshape(n, 1).copy(), P0.copy()

    def check(stage, k):
        x_ref = ref.x.ravel()
        rel_x = np.linalg.norm(ours.x - x_ref) / np.linalg.norm(x_ref)
        sigma_x = np.max(np.abs(ours.x - x_ref) / np.sqrt(np.diag(ref.P)))
        rel_P = scaled_difference(ours.covariance, ref.P)
        assert rel_x <= 1e-9, f"x after {stage} {k}: {rel_x:.2e}"
        assert sigma_x <= 1e-9, f"x after {stage} {k}: {sigma_x:.2e} sigma"
        assert rel_P <= 1e-9, f"P after {stage} {k}: {rel_P:.2e}"

    for k in range(500):
        u = rng.normal(0.0, 0.5)                            # i_ref [V]
        y = rng.normal(0.0, 1.0, 2) * np.sqrt(np.diag(R))   # sensor voltages [V]
        ours.predict(u)
        ref.predict(u=np.array([[u]]))
        check("predict", k)
        ours.update(y)
        ref.update(y.reshape(2, 1))
        check("update", k)


# -- covariance health over a long compiled run ----------------------------------

@pytest.mark.parametrize("overrides", [{}, {"filter_r_position": 1e-7}],
                         ids=["paper-R", "tiny-R_x"])
def test_covariance_stays_symmetric_psd_over_a_million_steps(overrides):
    """10**6 closed-loop samples (50 s) of the kalman_noise set-up: P stays
    symmetric (1e-12 rel) and positive semidefinite (min eig >= -1e-12 max eig,
    also for the correlation matrix), and still equals the DARE solution (1e-6)."""
    axis = setup(EXERCISE.resolve(overrides))
    sim = AxisSimulation(axis, seed=1)
    sim.advance(10**6)
    assert sim.status == radial_axis_loop.OK
    assert sim.step == 10**6
    P = np.array(sim.filter.covariance)
    assert np.all(np.isfinite(P))
    scale = np.abs(P).max()
    assert np.max(np.abs(P - P.T)) <= 1e-12 * scale
    eig = np.linalg.eigvalsh(0.5 * (P + P.T))
    assert eig.min() >= -1e-12 * eig.max()
    d = np.sqrt(np.diag(P))
    assert np.all(d > 0)
    assert np.linalg.eigvalsh(P / np.outer(d, d)).min() >= -1e-12
    # the covariance does not depend on the data: no drift from the Riccati solution
    A, _, C = model_matrices(axis)
    assert scaled_difference(P, dare_covariance(A, C, axis.filter_Q, axis.filter_R)) <= 1e-6


# -- steady state ----------------------------------------------------------------

@pytest.mark.parametrize("sensor_lag_s", LAGS_S)
def test_steady_state_kalman_equals_scipy_dare(sensor_lag_s):
    """analysis.steady_state_kalman: a-priori P equals scipy's DARE and K equals
    P C^T (C P C^T + R)^-1 (both within 1e-6 relative)."""
    axis = kalman_noise_setup(sensor_lag_s=sensor_lag_s)
    A, _, C = model_matrices(axis)
    Q, R = axis.filter_Q, axis.filter_R
    K, P = analysis.steady_state_kalman(axis.model, Q, R)
    P_dare = dare_covariance(A, C, Q, R)
    K_dare = P_dare @ C.T @ np.linalg.inv(C @ P_dare @ C.T + R)
    assert scaled_difference(P, P_dare) <= 1e-6
    assert K.shape == (A.shape[0], 2)
    np.testing.assert_allclose(K, K_dare, rtol=1e-6, atol=1e-6 * np.abs(K_dare).max())


@pytest.mark.parametrize("sensor_lag_s", LAGS_S)
def test_running_filter_converges_to_dare(sensor_lag_s):
    """After 0.2 s of closed loop (linear force law) the filter's predicted P
    and its gain equal the DARE solution (1e-6 relative)."""
    axis = kalman_noise_setup(sensor_lag_s=sensor_lag_s, nonlinear=False)
    sim = AxisSimulation(axis, seed=2)
    sim.advance(round(0.2 / T))
    assert sim.status == radial_axis_loop.OK
    A, _, C = model_matrices(axis)
    R = axis.filter_R
    P_dare = dare_covariance(A, C, axis.filter_Q, R)
    P = np.array(sim.filter.covariance)
    assert scaled_difference(P, P_dare) <= 1e-6
    K = P @ C.T @ np.linalg.inv(C @ P @ C.T + R)
    K_dare = P_dare @ C.T @ np.linalg.inv(C @ P_dare @ C.T + R)
    np.testing.assert_allclose(K, K_dare, rtol=1e-6, atol=1e-6 * np.abs(K_dare).max())


# -- consistency: normalised estimation error squared ------------------------------

N_RUNS = 50
CHECKPOINTS = [500, 1000, 2000]   # samples: 25, 50, 100 ms, after the P0 transient (~5 ms)


@pytest.mark.parametrize("use_estimate", [False, True], ids=["measured-fb", "estimated-fb"])
@pytest.mark.parametrize("sensor_lag_s", LAGS_S)
def test_nees_is_chi_square_consistent_on_linear_plant(sensor_lag_s, use_estimate):
    """Matched filter on the linear plant: the run-average NEES of the predicted
    estimate lies inside the two-sided 95 % chi-square interval for N n degrees
    of freedom divided by N (N = 50 seeded runs), at each checkpoint."""
    axis = kalman_noise_setup(sensor_lag_s=sensor_lag_s, nonlinear=False, use_estimate=use_estimate,
                              filter_q_velocity=None, filter_q_current=None,
                              filter_r_position=None, filter_r_current=None)
    n = axis.model.nstates
    nees = np.zeros((N_RUNS, len(CHECKPOINTS)))
    for run in range(N_RUNS):
        sim = AxisSimulation(axis, seed=1000 + run)
        done = 0
        for j, k in enumerate(CHECKPOINTS):
            sim.advance(k - done)
            done = k
            assert sim.status == radial_axis_loop.OK
            # after advance(k): plant holds the true state of sample k (x, v, i, x_d),
            # the filter the prediction x_{k|k-1} and P_{k|k-1}
            error = sim.plant[:n] - sim.filter.x
            P = sim.filter.covariance
            d = np.sqrt(np.diag(P))              # scale first: P spans 1e-14 ... 1e-6
            z = error / d
            nees[run, j] = z @ np.linalg.solve(P / np.outer(d, d), z)
    low, high = scipy.stats.chi2.ppf([0.025, 0.975], N_RUNS * n) / N_RUNS
    average = nees.mean(axis=0)
    assert np.all((low <= average) & (average <= high)), (
        f"average NEES {average} outside [{low:.3f}, {high:.3f}] (n = {n})")


@pytest.mark.parametrize("r_position_scale, consistent", [(1.0, True), (0.1, False), (10.0, False)])
def test_consistency_readouts_flag_a_mistuned_filter(r_position_scale, consistent):
    """The consistency readouts (Task 5, a dedicated 4 s run): with the eq. 16 R the error lies
    inside ±3σ about 99.7 % of the time and the mean (error/σ)² is near 1; R_x ten times too small
    makes the filter overconfident (mean > 3), ten times too large underconfident (< 0.3)."""
    from lab_modules.exercises.kalman_noise import consistency
    run = consistency(EXERCISE.resolve({"filter_r_position": 7.1e-4 * r_position_scale}))
    inside, mean_square = run["inside_3sigma_percent"], run["mean_nees"]
    if consistent:
        assert inside >= 99.0 and 0.8 <= mean_square <= 1.25
    elif r_position_scale < 1:
        assert inside < 90.0 and mean_square > 3.0
    else:
        assert inside == 100.0 and mean_square < 0.3
