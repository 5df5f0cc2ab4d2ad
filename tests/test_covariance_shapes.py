"""The filter debugger's 3D ellipsoids (lab_modules/estimators/covariance_shapes.py): the drawn
shape is the covariance's k-sigma set, and the box holds the prior's 3σ and both estimates."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lab_modules.estimators.covariance_shapes import SIGMAS, ellipsoid, state_box
from lab_modules.exercises import get


def _random_covariance(rng) -> np.ndarray:
    A = rng.normal(size=(3, 3)) * np.array([1e-6, 1e-3, 1.0])       # m, m/s, A: very different scales
    return A @ A.T + np.diag([1e-15, 1e-9, 1e-3])


@pytest.mark.parametrize("seed", range(5))
def test_the_drawn_sphere_turned_and_scaled_is_the_one_sigma_set(seed):
    rng = np.random.default_rng(seed)
    P, centre = _random_covariance(rng), rng.normal(size=3)
    shape = ellipsoid(centre, P)
    turned = Rotation.from_quat(np.roll(shape.wxyz(), -1)).as_matrix()     # what the viewer applies
    assert np.allclose(turned, shape.rotation) and np.isclose(np.linalg.det(turned), 1.0)
    directions = rng.normal(size=(200, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    surface = centre + (turned @ (directions * shape.semi_axes).T).T        # unit sphere scaled, turned, moved
    offsets = surface - centre
    mahalanobis = np.einsum("ij,jk,ik->i", offsets, np.linalg.inv(P), offsets)
    assert np.allclose(mahalanobis, 1.0, rtol=1e-6)


def test_a_singular_covariance_gives_a_flat_ellipsoid_not_nan():
    shape = ellipsoid(np.zeros(3), np.diag([4.0, 1.0, 0.0]))
    assert np.all(np.isfinite(shape.semi_axes)) and sorted(shape.semi_axes) == pytest.approx([0.0, 1.0, 2.0])


def _kalman_noise_sample() -> dict:
    exercise = get("kalman_noise")
    simulation = exercise.simulation(exercise.resolve({}))
    simulation.advance(4000)                                            # 0.2 s at 50 µs
    history = simulation.filter_tape().history()
    return history.sample(len(history) - 1)


def test_the_box_holds_the_priors_three_sigma_and_both_estimates_about_the_truth():
    sample = _kalman_noise_sample()
    box = state_box(sample, (0, 1, 2))
    assert np.all(box.known_truth) and np.allclose(box.point(sample["truth"]), 0.0)
    prior = box.ellipsoid(sample["x_prior"], sample["P_prior"])
    # the 3σ ellipsoid's extent along box axis j is 3 √(P_box[j, j])
    P_box = prior.rotation @ np.diag(prior.semi_axes**2) @ prior.rotation.T
    assert np.all(SIGMAS * np.sqrt(np.diag(P_box)) <= 1.0)
    for estimate in (sample["x_prior"], sample["x_post"]):
        assert np.all(np.abs(box.point(estimate)) <= 1.0)
    # the box only rescales: the correlations are those of P
    P = np.asarray(sample["P_prior"])[:3, :3]
    assert np.allclose(P_box, P / np.outer(box.lengths, box.lengths), rtol=1e-9)
    posterior = box.ellipsoid(sample["x_post"], sample["P_post"])
    assert np.all(posterior.semi_axes <= prior.semi_axes.max() * (1 + 1e-9))   # the update only shrinks P


def test_a_state_without_a_true_value_is_centred_on_the_prior_estimate():
    sample = _kalman_noise_sample()
    states = (0, 1, 3)                                                  # x_d, the sensor's lag state
    box = state_box(sample, states)
    assert list(box.known_truth) == [True, True, False]
    assert box.point(sample["x_prior"])[2] == 0.0
