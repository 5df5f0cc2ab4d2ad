"""``python -m app run NAME --filter-history FROM:TO [--branch ...] --json``: the printed history
recomputed from its own numbers, the branch, the χ² bounds and bad input."""

import json

import numpy as np
import pytest
import scipy.stats

from app.cli import main

SUPPORTED = ("kalman_noise", "lqg_vs_pid", "thrust_liftoff", "ekf_parameters", "ekf_disturbance", "maglev_tracking",
             "maglev_tuning", "adaptive_filter", "stiffness_map")


def printed(capsys, *argv) -> dict:
    assert main(["run", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def arrays(samples: list[dict], name: str) -> np.ndarray:
    return np.array([np.array(s[name], dtype=float) for s in samples])


@pytest.mark.parametrize("exercise", SUPPORTED)
def test_printed_history_obeys_the_filter_equations(capsys, exercise):
    result = printed(capsys, exercise, "--filter-history", "2500:2600")
    model = {name: np.array(result["filter"][name], dtype=float) for name in ("Gamma", "H", "R")}
    Gamma, H, R = (model[name] for name in ("Gamma", "H", "R"))
    samples = result["history"]["samples"]
    assert [s["sample"] for s in samples] == list(range(2500, 2600))
    x_prior, P_prior, K, nu, S, x_post, P_post, y, u, Phi, Q = (arrays(samples, name) for name in (
        "x_prior", "P_prior", "K", "innovation", "S", "x_post", "P_post", "y", "u", "Phi", "Q"))
    identity = np.eye(H.shape[1])
    linear = np.all(np.isfinite(Gamma))             # else x̂⁻ is the filter's own f(x̂⁺, u) (an EKF)
    integrated = np.all(np.isnan(Phi))              # the continuous-discrete EKF integrates P (eq. 2.45)
    assert integrated == exercise.startswith("maglev")
    for k in range(len(samples)):
        scale = np.abs(P_prior[k]).max()
        np.testing.assert_allclose(S[k], H @ P_prior[k] @ H.T + R, rtol=1e-12)            # S = H P⁻ Hᵀ + R
        np.testing.assert_allclose(K[k], P_prior[k] @ H.T @ np.linalg.inv(S[k]), rtol=1e-9,
                                   atol=1e-12 * np.abs(K[k]).max())                       # K = P⁻ Hᵀ S⁻¹
        np.testing.assert_allclose(nu[k], y[k] - H @ x_prior[k], rtol=1e-9, atol=1e-15)  # ν = y − H x̂⁻
        np.testing.assert_allclose(x_post[k], x_prior[k] + K[k] @ nu[k], rtol=1e-9, atol=1e-15)
        M = identity - K[k] @ H
        np.testing.assert_allclose(P_post[k], M @ P_prior[k] @ M.T + K[k] @ R @ K[k].T, rtol=1e-7,
                                   atol=1e-12 * scale)                                     # Joseph form
        for P in (P_prior[k], P_post[k]):
            assert np.array_equal(P, P.T)
            assert np.linalg.eigvalsh(P).min() >= -1e-12 * np.abs(P).max()
        if k + 1 < len(samples) and linear:
            np.testing.assert_allclose(x_prior[k + 1], Phi[k] @ x_post[k] + Gamma @ u[k], rtol=1e-9, atol=1e-15)
        if k + 1 < len(samples) and not integrated:       # P⁻ = Φ_k P⁺ Φ_kᵀ + Q_k with the sample's own Φ_k, Q_k
            np.testing.assert_allclose(P_prior[k + 1], Phi[k] @ P_post[k] @ Phi[k].T + Q[k], rtol=1e-9,
                                       atol=1e-12 * scale)


def test_branch_with_unchanged_settings_prints_the_history_bit_for_bit(capsys):
    result = printed(capsys, "kalman_noise", "--filter-history", "2500:2600", "--branch", "q_scale=1,r_scale=1@2550")
    original, same = result["history"]["samples"][50:], result["branch"]["samples"]
    assert [s["sample"] for s in same] == list(range(2550, 2600))
    assert same == original
    changed = printed(capsys, "kalman_noise", "--filter-history", "2500:2600", "--branch", "q_scale=10@t=0.1275")
    assert changed["branch"]["from_sample"] == 2550 and changed["branch"]["samples"] != original


def test_bounds_are_scipys_and_a_mistuned_filter_is_named(capsys):
    tuned = printed(capsys, "kalman_noise", "--filter-history", "2000:4000")["history"]
    mistuned = printed(capsys, "kalman_noise", "--filter-history", "2000:4000", "--set", "filter_r_position=0.071",
                       "--set", "filter_r_current=10")["history"]
    for result in (tuned, mistuned):
        for name, dof in (("NEES", 3), ("NIS", 2)):
            test = result[name]
            total = test["independent_samples"] * dof
            assert test["dof"] == dof
            assert test["lower_95"] == pytest.approx(scipy.stats.chi2.ppf(0.025, total) / test["independent_samples"],
                                                     rel=1e-14)
            assert test["upper_95"] == pytest.approx(scipy.stats.chi2.ppf(0.975, total) / test["independent_samples"],
                                                     rel=1e-14)
    assert tuned["NEES"]["inside"] and tuned["NIS"]["inside"]
    assert not mistuned["NIS"]["inside"] and mistuned["NIS"]["verdict"].startswith("too cautious")


@pytest.mark.parametrize("argv, words", [
    (["kalman_noise", "--filter-history", "10"], "FROM:TO"),
    (["kalman_noise", "--filter-history", "20:10"], "FROM < TO"),
    (["kalman_noise", "--filter-history", "0:5000"], "at most 4000"),
    (["kalman_noise", "--filter-history", "0:10", "--branch", "q_scale=10"], "SETTINGS@SAMPLE"),
    (["kalman_noise", "--filter-history", "0:10", "--branch", "k_scale=10@5"], "q_scale"),
    (["kalman_noise", "--filter-history", "0:10", "--branch", "q_scale=nan@5"], "out of range"),
    (["kalman_noise", "--filter-history", "0:10", "--branch", "q_scale=2@50"], "outside"),
    (["kalman_noise", "--branch", "q_scale=2@5"], "needs --filter-history"),
    (["rotor_at_speed", "--filter-history", "0:10"], "no sampled Kalman filter"),
    (["maglev_tracking", "--set", "filter=continuous-time", "--filter-history", "0:10"], "no sampled Kalman filter"),
])
def test_bad_input_exits_2_with_one_line(capsys, argv, words):
    assert main(["run", *argv]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and error.startswith("error: ") and words in error
