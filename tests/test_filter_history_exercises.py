"""The filter debugger's history for the filters whose prediction is their own (EKFs linearised
about their estimate, filters scheduled on their operating point, the continuous-discrete EKF):
the replay equals the compiled filter, P stays symmetric PSD, an unchanged branch is the history
bit for bit, a changed one re-linearises about its own estimates, the bounds are scipy's, and
the tape is small."""

import numpy as np
import pytest
import scipy.stats

from lab_modules.estimators import extended_kalman as ef
from lab_modules.estimators.filter_consistency import consistency
from lab_modules.estimators.filter_history import ARRAY_FIELDS, CAPACITY, branch, predict
from lab_modules.exercises import get


def compiled_prior(simulation) -> tuple[np.ndarray, np.ndarray]:
    """The compiled filter's x̂⁻ and P⁻ for the sample after the last one run."""
    if hasattr(simulation, "loop"):                               # the axial bearing's filter bank
        loop = simulation.loop
        return loop.filter_z[loop.shown], loop.filter_P[loop.shown]
    if hasattr(simulation, "priors"):                             # the recording's observer
        return simulation.priors[simulation.position, :3], simulation.priors[simulation.position, 3:].reshape(3, 3)
    return simulation.x_hat, simulation.P


EXERCISES = ("ekf_parameters", "ekf_disturbance", "maglev_tracking", "maglev_tuning", "adaptive_filter",
             "stiffness_map")


@pytest.fixture(scope="module", params=EXERCISES)
def run(request):
    exercise = get(request.param)
    simulation = exercise.simulation(exercise.resolve({}))
    rows = sum(len(simulation.advance(500)) for _ in range(5))
    return request.param, simulation, simulation.filter_tape().history(), rows


def test_replay_equals_the_compiled_filter(run):
    _, simulation, history, rows = run
    assert len(history) == rows == 2500
    x, P = predict(history.model, history.x_post[-1], history.P_post[-1], history.u[-1])[:2]
    x_compiled, P_compiled = compiled_prior(simulation)
    sigma = np.sqrt(np.diag(P_compiled))
    assert np.all(np.abs(x - x_compiled) <= 1e-9 * sigma)
    np.testing.assert_allclose(P, P_compiled, rtol=1e-8, atol=1e-10 * np.abs(P_compiled).max())


def test_covariances_stay_symmetric_positive_semidefinite_and_K_is_P_Ht_over_S(run):
    _, _, history, _ = run
    H, R = history.model.H, history.model.R
    for P in (history.P_prior, history.P_post):
        assert np.array_equal(P, np.swapaxes(P, 1, 2))
        assert np.all(np.linalg.eigvalsh(P).min(axis=1) >= -1e-12 * np.abs(P).max(axis=(1, 2)))
    S = H @ history.P_prior @ H.T + R                                   # S = H P⁻ Hᵀ + R
    np.testing.assert_allclose(history.S, S, rtol=1e-12)
    K = history.P_prior @ H.T @ np.linalg.inv(S)                        # K = P⁻ Hᵀ S⁻¹
    np.testing.assert_allclose(history.K, K, rtol=1e-9, atol=1e-12 * np.abs(K).max())


def test_the_prediction_uses_each_samples_own_matrices(run):
    name, _, history, _ = run
    integrated = np.isnan(history.Phi).all()
    assert integrated == name.startswith("maglev")                       # eq. 2.45 integrates P: no Φ_k
    if not integrated:
        Phi, Q, P = history.Phi[:-1], history.Q[:-1], history.P_post[:-1]
        expected = Phi @ P @ np.swapaxes(Phi, 1, 2) + Q                   # P⁻ = Φ_k P⁺ Φ_kᵀ + Q_k
        np.testing.assert_allclose(history.P_prior[1:], expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max())
        assert not np.array_equal(history.Phi[0], history.Phi[-1])      # linearised (scheduled) per sample


@pytest.mark.parametrize("row", [0, 1, 1234])
def test_branch_with_unchanged_settings_is_the_history_bit_for_bit(run, row):
    _, _, history, _ = run
    same = branch(history, row, history.model.scaled(1.0, 1.0), horizon=500)
    assert same.first_sample == history.first_sample + row and len(same) == 500
    for field in ARRAY_FIELDS:
        assert np.array_equal(getattr(same, field), getattr(history, field)[row:row + 500], equal_nan=True), field


def test_a_branch_relinearises_about_its_own_estimates():
    exercise = get("ekf_disturbance")
    simulation = exercise.simulation(exercise.resolve({}))
    simulation.advance(2500)
    history = simulation.filter_tape().history()
    rerun = branch(history, 1000, history.model.scaled(q_scale=100.0))
    assert not np.array_equal(rerun.x_post[-1], history.x_post[-1])
    F, Phi = np.empty((5, 5)), np.empty((5, 5))
    physics = ef.physics_vector(simulation.setup.rig, simulation.setup.filter_sensor_lag_s)
    for k in (10, 500, len(rerun) - 2):
        ef.jacobian(ef.NONLINEAR, rerun.x_post[k], physics, F)                 # F at the branch's x̂⁺
        ef.transition_matrix(F, simulation.sample_time_s, Phi)
        assert np.array_equal(rerun.Phi[k], Phi)
        assert not np.array_equal(rerun.Phi[k], history.Phi[1000 + k])
        np.testing.assert_array_equal(rerun.Q[k], 100.0 * history.Q[1000 + k])


def test_bounds_are_scipys_chi2_quantiles(run):
    name, _, history, _ = run
    tests = {test.name: test for test in consistency(history, window=1500)}
    assert set(tests) == ({"NIS"} if name == "maglev_tuning" else {"NEES", "NIS"})    # a recording has no truth
    for test in tests.values():
        total = test.independent_samples * test.dof
        assert test.lower == pytest.approx(scipy.stats.chi2.ppf(0.025, total) / test.independent_samples, rel=1e-14)
        assert test.upper == pytest.approx(scipy.stats.chi2.ppf(0.975, total) / test.independent_samples, rel=1e-14)
    assert tests["NIS"].dof == 1 + name.startswith("ekf")


def test_the_tape_is_smaller_per_sample_than_the_scopes_row(run):
    """Measured: the tape's bytes per sample against one scope row (time and every column)."""
    _, simulation, _, _ = run
    tape = simulation.filter_tape()
    per_sample = tape.nbytes / tape.count
    scope_row = 8 * (1 + len(simulation.columns))
    assert per_sample <= 80 and per_sample < scope_row          # u, y, truth, time: 72 B at most, and the priors
    assert tape.capacity == CAPACITY and per_sample * (CAPACITY + 1000) < 400e3
