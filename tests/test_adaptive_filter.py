"""Exercise ``adaptive_filter`` (paper 002): the 4-state filter against filterpy,
the scheduled model, consistency with P, and the paper's claims."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

from lab_modules.estimators.scheduled_kalman import (
    AxialKalmanFilter,
    model_matrices,
    physics_vector,
    predict_exact_force,
)
from lab_modules.estimators.stiffness_identification import lsm_factors
from lab_modules.exercises.adaptive_filter import EXERCISE, setup
from lab_modules.loops.axial_bearing_loop import LoopSimulation, Segment, column
from lab_modules.plants.axial_bearing import AXIAL
from tests.test_stiffness_map import run_app

PHYSICS = physics_vector(AXIAL.mass_kg, 1e-4, 1e-4, 1000.0, 9.81, 8e-5, 1e-2, 8.3e-5,
                         AXIAL.k_magnet_n_m2_per_a2, AXIAL.nominal_gap_m, AXIAL.bias_current_a)


@pytest.fixture(scope="module")
def metrics():
    return EXERCISE.metrics(EXERCISE.resolve({}), EXERCISE.default_duration_s)


@pytest.mark.parametrize("claim", EXERCISE.claims, ids=lambda c: c.metric)
def test_claim_holds_at_the_defaults(claim, metrics):
    value = claim.value_in(metrics)
    assert claim.holds(value), f"{claim.quantity}: {value} not in {claim.accept_text()}"


def test_filter_matches_filterpy_step_by_step():
    """Same model, same data: the compiled predict/correct against filterpy's KalmanFilter."""
    k_i, k_s = 8.7, 17_360.0
    ours = AxialKalmanFilter(k_i, k_s, PHYSICS, P0=np.diag([20e-6, 1e-3, 1.0, 20e-3]) ** 2)
    reference = KalmanFilter(dim_x=4, dim_z=1, dim_u=2)
    reference.F, reference.B, reference.Q = ours.A.copy(), ours.B.copy(), ours.Q.copy()
    reference.H = np.array([[0.0, 0.0, 0.0, 1.0]])
    reference.R = np.array([[PHYSICS[7]]])
    reference.x, reference.P = ours.z.copy().reshape(4, 1), ours.P.copy()
    rng = np.random.default_rng(5)
    for _ in range(300):
        y, current = rng.normal(0.0, 0.05), rng.normal(0.5, 0.2)
        ours.update(y)
        reference.update(np.array([[y]]))
        assert ours.z == pytest.approx(reference.x.ravel(), rel=1e-9, abs=1e-15)
        assert ours.P == pytest.approx(reference.P, rel=1e-9, abs=1e-20)
        ours.predict(current)
        reference.predict(u=np.array([[current], [1.0]]))
    assert ours.P == pytest.approx(reference.P, rel=1e-9, abs=1e-20)


def test_ekf_prediction_uses_the_force_law():
    z = np.array([0.3e-3, 0.01, -2.0, 0.25])
    P = np.eye(4) * 1e-9
    A, B, Q = np.zeros((4, 4)), np.zeros((4, 2)), np.zeros((4, 4))
    current, T, m = 0.8, PHYSICS[1], PHYSICS[0]
    expected_accel = (AXIAL.force_n(current, z[0]) + z[2]) / m - 9.81
    x0, v0 = z[0], z[1]
    predict_exact_force(z, P, PHYSICS, current, A, B, Q)
    assert z[1] == pytest.approx(v0 + T * expected_accel, rel=1e-12)
    assert z[0] == pytest.approx(x0 + T * v0 + 0.5 * T * T * expected_accel, rel=1e-12)
    k_i, k_s = AXIAL.tangent_factors(current, x0)
    A_tangent, B_tangent = np.zeros((4, 4)), np.zeros((4, 2))
    model_matrices(k_i, k_s, PHYSICS, A_tangent, B_tangent)
    assert A == pytest.approx(A_tangent)


def test_no_intercept_factors_reproduce_the_force_at_their_point():
    """Why the scheduled filter has no bias: k_i i + k_s x of the local fit equals F(i, x) there."""
    rng = np.random.default_rng(2)
    i, x = rng.uniform(-1.5, 1.5, 200), rng.uniform(-0.5e-3, 0.5e-3, 200)
    k_i, k_s = lsm_factors(i, x)
    assert np.max(np.abs(k_i * i + k_s * x - AXIAL.force_n(i, x))) < 0.01
    k_i0, k_s0 = AXIAL.centre_factors()
    assert np.max(np.abs(k_i0 * i + k_s0 * x - AXIAL.force_n(i, x))) > 2.0


def test_fixed_filter_bias_is_the_model_error_at_the_operating_point(metrics):
    k_i, k_s = AXIAL.centre_factors()
    for (current, position_mm), bias in zip(metrics["operating_points_current_a_position_mm"],
                                            metrics["force_bias_fixed_n"]):
        x = position_mm * 1e-3
        assert bias == pytest.approx(float(AXIAL.force_n(current, x)) - (k_i * current + k_s * x), abs=0.05)


def test_error_matches_the_filters_covariance_when_the_plant_has_the_modelled_force_walk():
    values = EXERCISE.resolve({})
    loop_setup = replace(setup(values), segments=(Segment(0.0, 0.0, 0.0),), period_s=2.0,
                         plant_force_walk_n2=values["q_force_n2"])
    trace = LoopSimulation(loop_setup, seed=3).advance(20_000)
    keep = trace[:, 0] > 0.05
    error = column(trace, "fixed_x_m")[keep] - column(trace, "x_true_m")[keep]
    sigma = np.mean(column(trace, "fixed_x_sigma_m")[keep])
    assert np.std(error) == pytest.approx(sigma, rel=0.1)


def test_load_steps_beyond_the_bearings_capacity_touch_down():
    values = EXERCISE.resolve({"point1_force_n": 20.0, "point1_position_mm": -0.5, "load_ramp_ms": 1.0})
    simulation = EXERCISE.simulation(values)
    simulation.advance(6000)
    assert "Touchdown" in simulation.status_message()


@pytest.mark.parametrize("setting, tokens", [
    ("feedback=kalman", ["feedback", "measured", "fbfnn"]),
    ("point1_position_mm=0.8", ["point1_position_mm", "-0.5", "0.5"]),
    ("q_force_n2=nan", ["q_force_n2"]),
])
def test_cli_bad_input_exits_2_with_one_line(setting, tokens):
    result = run_app("run", "adaptive_filter", "--set", setting)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1
    assert all(token in lines[0] for token in tokens), lines[0]
