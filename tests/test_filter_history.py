"""The filter debugger's data: the replayed history (against filterpy and the compiled loop), the
bounded tape, the branch (unchanged settings: bit for bit) and NEES/NIS with χ² bounds."""

import numpy as np
import pytest
import scipy.stats
from filterpy.kalman import KalmanFilter as ReferenceFilter

from lab_modules.estimators.filter_consistency import bounds, consistency
from lab_modules.estimators.filter_history import (
    ARRAY_FIELDS,
    FilterModel,
    FilterTape,
    branch,
    predict,
    replay,
)
from lab_modules.exercises import get

T = 1e-3


def tracking_model(q: float = 1e-2, r: float = 1e-4) -> FilterModel:
    """A cart pushed by a known force u: position measured, velocity driven by white noise."""
    return FilterModel.of("cart", T, [[1.0, T], [0.0, 1.0]], [0.5 * T * T, T], [[1.0, 0.0]],
                          np.diag([0.0, q]) + 1e-12 * np.eye(2), [r], (("x", "m"), ("v", "m/s")),
                          (("position", "m"),))


def cart_run(model: FilterModel, samples: int, seed: int = 1, q: float = 1e-2, r: float = 1e-4):
    """(u, y, truth) of the cart with process variance q and sensor variance r per sample."""
    rng = np.random.default_rng(seed)
    u = np.sin(np.arange(samples) * 0.01)[:, None]
    x, truth, y = np.zeros(2), np.empty((samples, 2)), np.empty((samples, 1))
    for k in range(samples):
        truth[k] = x
        y[k] = x[0] + np.sqrt(r) * rng.standard_normal()
        x = model.Phi @ x + model.Gamma @ u[k] + np.array([0.0, np.sqrt(q) * rng.standard_normal()])
    return u, y, truth


def taped(model, u, y, truth, chunk: int = 250, capacity: int = 2000) -> FilterTape:
    """A tape fed chunk by chunk, each chunk's prior from a replay of everything before it."""
    tape = FilterTape(model, capacity)
    full = replay(model, np.zeros(2), np.eye(2), u, y)
    for first in range(0, len(y), chunk):
        x0, P0 = (np.zeros(2), np.eye(2)) if first == 0 else (full["x_prior"][first], full["P_prior"][first])
        last = first + chunk
        tape.record(first, x0, P0, np.arange(first, last) * T, u[first:last], y[first:last], truth[first:last])
    return tape


def test_replay_equals_filterpy():
    model = tracking_model()
    u, y, _ = cart_run(model, 300)
    ours = replay(model, np.zeros(2), np.eye(2), u, y)
    reference = ReferenceFilter(dim_x=2, dim_z=1, dim_u=1)
    reference.F, reference.B, reference.H = model.Phi, model.Gamma, model.H
    reference.Q, reference.R, reference.x, reference.P = model.Q, model.R, np.zeros(2), np.eye(2)
    for k in range(len(y)):
        np.testing.assert_allclose(ours["x_prior"][k], reference.x, rtol=1e-9, atol=1e-12)
        reference.update(y[k])
        np.testing.assert_allclose(ours["K"][k], reference.K, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(ours["S"][k], reference.S, rtol=1e-9)
        np.testing.assert_allclose(ours["innovation"][k], reference.y, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(ours["P_post"][k], reference.P, rtol=1e-7, atol=1e-15)
        reference.predict(u=u[k])


def test_tape_is_bounded_and_keeps_the_newest_samples():
    model = tracking_model()
    u, y, truth = cart_run(model, 6000)
    tape = taped(model, u, y, truth)
    history = tape.history()
    assert 2000 <= len(history) < 2000 + 250 and tape.count == len(history)
    assert history.first_sample + len(history) == 6000
    full = replay(model, np.zeros(2), np.eye(2), u, y)
    for name in ("x_post", "P_post", "K"):
        assert np.array_equal(getattr(history, name), full[name][history.first_sample:])
    tape.record(9000, np.zeros(2), np.eye(2), [9.0], [[0.0]], [[0.0]], [[0.0, 0.0]])
    assert tape.history().first_sample == 9000 and len(tape.history()) == 1    # a gap: the old record is stale


def test_the_tape_refuses_a_full_measurement_covariance():
    model = FilterModel.of("two sensors", T, np.eye(2), [0.0, 0.0], np.eye(2), np.eye(2), [[1.0, 0.5], [0.5, 1.0]],
                           (("a", "m"), ("b", "m")), (("a", "m"), ("b", "m")))
    with pytest.raises(ValueError, match="diagonal R"):
        FilterTape(model)


@pytest.fixture(scope="module")
def kalman_noise_run():
    exercise = get("kalman_noise")
    simulation = exercise.simulation(exercise.resolve({}))
    for _ in range(12):
        simulation.advance(500)
    return simulation, simulation.filter_tape().history()


def test_replay_equals_the_compiled_loops_filter(kalman_noise_run):
    simulation, history = kalman_noise_run
    x, P = predict(history.model, history.x_post[-1], history.P_post[-1], history.u[-1])[:2]
    sigma = np.sqrt(np.diag(P))
    assert np.all(np.abs(x - simulation.filter.x) < 1e-9 * sigma)
    np.testing.assert_allclose(P, simulation.filter.covariance, rtol=1e-9, atol=1e-12 * np.abs(P).max())
    assert len(history) >= 2000 and history.first_sample + len(history) == simulation.step


def test_covariances_stay_symmetric_positive_semidefinite(kalman_noise_run):
    _, history = kalman_noise_run
    for P in (history.P_prior, history.P_post):
        assert np.array_equal(P, np.swapaxes(P, 1, 2))
        assert np.all(np.linalg.eigvalsh(P).min(axis=1) >= -1e-12 * np.abs(P).max(axis=(1, 2)))


@pytest.mark.parametrize("row", [0, 1, 1234])
def test_branch_with_unchanged_settings_is_the_history_bit_for_bit(kalman_noise_run, row):
    _, history = kalman_noise_run
    same = branch(history, row, history.model.scaled(1.0, 1.0), horizon=500)
    assert same.first_sample == history.first_sample + row and len(same) == 500
    for name in ARRAY_FIELDS:
        assert np.array_equal(getattr(same, name), getattr(history, name)[row:row + 500], equal_nan=True), name


def test_branch_with_more_process_noise_trusts_the_measurements_more(kalman_noise_run):
    _, history = kalman_noise_run
    more_q = branch(history, 1000, history.model.scaled(q_scale=10.0))
    assert np.array_equal(more_q.y, history.y[1000:]) and np.array_equal(more_q.u, history.u[1000:])
    assert np.all(np.abs(more_q.K[-1, 0, 0]) > np.abs(history.K[-1, 0, 0]))
    assert np.trace(more_q.P_prior[0]) > np.trace(history.P_prior[1000])


def test_bounds_are_scipys_chi2_quantiles(kalman_noise_run):
    _, history = kalman_noise_run
    for result in consistency(history, window=1500):
        total = result.independent_samples * result.dof
        assert result.lower == pytest.approx(scipy.stats.chi2.ppf(0.025, total) / result.independent_samples,
                                             rel=1e-14)
        assert result.upper == pytest.approx(scipy.stats.chi2.ppf(0.975, total) / result.independent_samples,
                                             rel=1e-14)
    nees, nis = consistency(history, window=1500)
    assert nis.samples == nis.independent_samples == 1500 and nis.dof == 2
    assert nees.dof == 3 and 1 <= nees.independent_samples < 1500     # correlated errors: fewer samples
    assert bounds(1, 1) == pytest.approx(tuple(scipy.stats.chi2.ppf([0.025, 0.975], 1)))


def test_well_tuned_filters_are_inside_their_bounds_and_mistuned_ones_outside(kalman_noise_run):
    _, history = kalman_noise_run
    assert all(result.inside for result in consistency(history))
    for r_scale, verdict in ((100.0, "too cautious"), (0.01, "overconfident")):
        mistuned = branch(history, 0, history.model.scaled(r_scale=r_scale))
        _, nis = consistency(mistuned)
        assert not nis.inside and nis.verdict.startswith(verdict)
    model = tracking_model()
    u, y, truth = cart_run(model, 3000)
    tuned = taped(model, u, y, truth).history()
    assert all(result.inside for result in consistency(tuned))
    nees, nis = consistency(branch(tuned, 0, model.scaled(q_scale=1e-4)))
    assert not nees.inside and not nis.inside and nees.verdict.startswith("overconfident")
