"""The MISO ADALINE of paper 002 §C (``estimators.adaline.miso_step``/``miso_run``): the
Widrow-Hoff rule itself, convergence to numpy's least squares on exciting data, and
the force it identifies online in the stiffness map's closed loop."""

import numpy as np
import pytest

from lab_modules.estimators.adaline import miso_run, miso_step, siso_run, siso_step
from lab_modules.exercises.stiffness_map import EXERCISE, adaline_run
from lab_modules.plants.axial_bearing import AXIAL


def test_one_step_is_eq_24_for_every_weight():
    weights, inputs, target, rate = np.array([9.0, 2.0]), np.array([0.6, -0.2]), 5.5, 0.1
    expected_error = target - weights @ inputs
    expected = weights + rate * expected_error * inputs
    estimate = miso_step(weights, inputs, target, rate)
    assert estimate == pytest.approx(9.0 * 0.6 - 0.4)
    assert weights == pytest.approx(expected)
    # with one input it is the SISO rule
    w = np.array([5.0])
    miso_step(w, np.array([0.76]), 5.08, 0.0175)
    assert w[0] == pytest.approx(siso_step(5.0, 0.76, 5.08, 0.0175))


def test_lms_converges_to_numpy_lstsq_on_exciting_data():
    """Random operating points around i = 0.4 A, x = 0.1 mm (±0.1 A, ±0.05 mm): the weights of
    a slow LMS, averaged over the last 20 000 samples, approach the batch least squares of the
    same samples (the plane F = k_i i + k_s x, no constant) within 1 %."""
    rng = np.random.default_rng(3)
    n = 200_000
    current = 0.4 + rng.uniform(-0.1, 0.1, n)
    position_mm = 0.1 + rng.uniform(-0.05, 0.05, n)
    force = AXIAL.force_n(current, position_mm * 1e-3)
    theta, *_ = np.linalg.lstsq(np.column_stack([current, position_mm]), force, rcond=None)
    weights, out = np.zeros(2), np.empty((n, 3))
    miso_run(weights, current, position_mm, force, 0.05, out)
    averaged = out[-20_000:, 1:].mean(axis=0)
    assert averaged == pytest.approx(theta, rel=0.01)
    prediction = out[-20_000:, 0]
    lstsq_rms = np.sqrt(np.mean((np.column_stack([current, position_mm]) @ theta - force)[-20_000:] ** 2))
    assert np.sqrt(np.mean((prediction - force[-20_000:]) ** 2)) < 1.5 * lstsq_rms


@pytest.fixture(scope="module")
def run():
    return adaline_run(EXERCISE.resolve({}))


def test_miso_identifies_the_magnet_force_in_the_closed_loop(run):
    """Rotor held at the centre under its weight, k_Magnet −10 % at 100 ms, F̂ from 0:
    RMS(F̂ − F) ≤ 0.05 N (1 % of the 5.08 N carried) in 50-100 ms and 150-200 ms, and no
    worse than 1.25 × the residual of numpy's least squares of the same samples."""
    summary = run["miso_summary"]
    for k in (0, 1):
        assert summary["rms_error_n"][k] <= 0.05
        assert summary["rms_error_n"][k] <= 1.25 * summary["lstsq_rms_n"][k]
    # the well-excited weight matches the batch answer and, at x = 0 (F linear in i), Table 4's k_i
    assert summary["weights_end"][0][0] == pytest.approx(summary["lstsq_weights"][0][0], rel=0.005)
    assert summary["weights_end"][0][0] == pytest.approx(10.05, rel=0.01)
    # after the step the force is carried by a larger current: w_i follows k_i·F/F ... lower by ~10 %
    assert summary["weights_end"][1][0] == pytest.approx(0.9 * 10.05, rel=0.01)


def test_miso_starts_from_zero_and_is_within_one_percent_after_50_ms(run):
    t, estimate, force = run["t"], run["miso"][:, 0], run["force"]
    assert estimate[0] == 0.0
    late = (t >= 0.05) & (t < 0.1)
    assert abs(np.mean(estimate[late] - force[late])) < 0.01 * AXIAL.weight_n


def test_siso_run_is_siso_step_at_every_sample_digit_for_digit():
    rng = np.random.default_rng(3)
    regressors, targets = rng.uniform(-1.0, 1.0, 500), rng.normal(6.0, 1.0, 500)
    weight, expected = 5.0, np.empty(500)
    for k in range(500):                                   # the slow, obvious twin
        expected[k] = weight * regressors[k]
        weight = siso_step(weight, regressors[k], targets[k], 0.05)
    out = np.empty(500)
    assert siso_run(5.0, regressors, targets, 0.05, out) == weight
    assert np.array_equal(out, expected)
    assert abs(weight - 5.0) > 0.1                         # it learned something
