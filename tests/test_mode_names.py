"""Physical mode names on the pole map (issue 11, defect 15): ``analysis.name_modes`` names
each eigenvalue after the states that take part in it (participation factors), every
exercise with ``mode_matrices`` names its sets that way, and the names follow the physics
when a slider moves the poles."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from app.panels import pole_map
from lab_modules import analysis
from lab_modules.evaluation import poles as pole_sets
from lab_modules.exercises import Analysis, get, registry
from lab_modules.exercises._common import axis_loop_modes, axis_mode_matrices
from lab_modules.exercises.kalman_noise import setup
from lab_modules.plants.radial_bearing import RIG

WITH_MATRICES = sorted(name for name, e in registry().items() if e.mode_matrices(e.resolve()))


def poles_of(exercise, values) -> dict:
    result = exercise.analyse(values)
    return (result if isinstance(result, Analysis) else next(iter(result))).poles


def named(exercise, values) -> list[pole_sets.Mode]:
    view = pole_sets.view(exercise, values, poles_of(exercise, values))
    return pole_sets.modes(view.poles, view.names, view.shares)


def test_at_least_the_radial_axis_exercises_name_their_modes():
    assert {"kalman_noise", "ekf_parameters", "ekf_disturbance", "lqg_vs_pid", "sensor_placement"} <= set(WITH_MATRICES)


@pytest.mark.parametrize("name", WITH_MATRICES)
def test_every_pole_of_a_set_with_a_matrix_gets_a_physical_name(name):
    """The matrices' eigenvalues are the set's poles (else a pole stays unnamed), and each
    mode's participation shares sum to 1."""
    exercise = get(name)
    values = exercise.resolve()
    matrices = exercise.mode_matrices(values)
    poles = poles_of(exercise, values)
    assert set(matrices) <= set(poles), set(matrices) - set(poles)
    for mode in named(exercise, values):
        if mode.set_name in matrices:
            assert mode.name, (mode.set_name, mode.pole)
            assert sum(share for _, share in mode.shares) == pytest.approx(1.0)
    for A, states, _ in matrices.values():
        assert len(states) == np.shape(A)[0]
        assert all("[" in label and label.endswith("]") for label, _ in states), states   # units


def test_names_come_from_eigenvectors_not_indices():
    """Two decoupled blocks: permuting the states permutes nothing in the names; rescaling a
    state (m -> µm) changes no participation share; a coupled pair splits its share."""
    A = np.array([[0.0, 1.0, 0.0], [-400.0, -4.0, 0.0], [0.0, 0.0, -50.0]])
    states = [("x [m]", "mass"), ("v [m/s]", "mass"), ("i [A]", "coil")]
    modes = {round(m.pole_s.real): m for m in analysis.name_modes(A, states)}
    assert modes[-2].name == "mass" and modes[-50].name == "coil"
    order = [2, 0, 1]
    permuted = analysis.name_modes(A[np.ix_(order, order)], [states[k] for k in order])
    assert {round(m.pole_s.real): m.name for m in permuted} == {k: m.name for k, m in modes.items()}
    scale = np.diag([1e6, 1e6, 1.0])                  # x and v in µm, µm/s
    scaled = analysis.name_modes(scale @ A @ np.linalg.inv(scale), states)
    for m in scaled:
        reference = modes[round(m.pole_s.real)]
        assert dict(m.shares) == pytest.approx(dict(reference.shares), abs=1e-9)
    coupled = A.copy()
    coupled[1, 2] = 1e3                               # the coil drives the mass: still its own mode
    coil = next(m for m in analysis.name_modes(coupled, states) if abs(m.pole_s + 50) < 1e-6)
    assert coil.name == "coil" and dict(coil.shares)["i [A]"] > 0.5


def test_participation_against_eigenvectors_directly():
    """p_ik = v_ik w_ik with V⁻¹ V = I; cross-checked with scipy's left eigenvectors."""
    rng = np.random.default_rng(1)
    A = rng.normal(size=(5, 5))
    lam, p = analysis.participation(A)
    w_lam, left, right = scipy.linalg.eig(A, left=True, right=True)
    for k, value in enumerate(lam):
        j = int(np.argmin(np.abs(w_lam - value)))
        v, w = right[:, j], left[:, j].conj()
        raw = np.abs(v * w / (w @ v))
        assert p[:, k] == pytest.approx(raw / raw.sum(), rel=1e-8)


def test_separation_filter_error_modes_carry_the_same_name_in_the_loop():
    """With the estimate fed back (kalman_noise, feedback = estimated) the loop's poles are the
    control poles and the filter's error poles (separation principle): the loop names the
    latter exactly as the filter-error set does."""
    exercise = get("kalman_noise")
    axis = setup(exercise.resolve()).with_changes(use_estimate=True)
    A, states = axis_loop_modes(axis)
    loop = analysis.name_modes(A, states, RIG.sample_time_s)
    error_A, error_states, T = axis_mode_matrices(axis, "loop", "error")["error"]
    for m in analysis.name_modes(error_A, error_states, T):
        twin = min(loop, key=lambda n: abs(n.pole_s - m.pole_s))
        assert abs(twin.pole_s - m.pole_s) < 1e-6 * abs(m.pole_s)
        assert twin.name == m.name and "estimate error" in m.name
    control_names = {n.name for n in loop if "estimate error" not in n.name}
    assert {"PID integrator", "PID derivative filter", "rotor position/velocity (suspension mode)"} <= control_names


def _mode(exercise, values, set_name, name) -> pole_sets.Mode:
    found = [m for m in named(exercise, values) if m.set_name == set_name and m.label == name]
    assert len(found) == 1, (name, [(m.label, m.pole) for m in named(exercise, values) if m.set_name == set_name])
    return found[0]


def test_names_follow_the_physics_when_sliders_move():
    """kalman_noise: a longer integral time T_I slows the 'PID integrator' pole (≈ −1/T_I for a
    well-separated integrator) and leaves the suspension mode where it was; a larger gain K
    stiffens the suspension mode (higher f_n) and the name stays on it."""
    exercise = get("kalman_noise")
    base = exercise.resolve()
    integrator = _mode(exercise, base, "closed loop", "PID integrator")
    suspension = _mode(exercise, base, "closed loop", "rotor position/velocity (suspension mode)")
    slow = exercise.resolve({"integral_time_ms": 4 * base["integral_time_ms"]})
    slow_integrator = _mode(exercise, slow, "closed loop", "PID integrator")
    assert abs(slow_integrator.pole) < 0.5 * abs(integrator.pole)
    assert abs(slow_integrator.pole.real) == pytest.approx(1e3 / slow["integral_time_ms"], rel=0.3)
    assert _mode(exercise, slow, "closed loop", suspension.label).natural_hz == pytest.approx(
        suspension.natural_hz, rel=0.1)
    stiff = exercise.resolve({"pid_gain": 1.5 * base["pid_gain"]})
    stiff_suspension = _mode(exercise, stiff, "closed loop", suspension.label)
    assert stiff_suspension.natural_hz > 1.1 * suspension.natural_hz
    assert pole_map.follow(pole_sets.view(exercise, stiff, poles_of(exercise, stiff)), suspension).pole == \
        stiff_suspension.pole


def test_lqg_regulator_and_filter_error_names():
    """lqg_vs_pid: the regulator's states are x, v, i and the position integral ξ (eq. 19);
    every regulator mode is named after one of them, one of them after the integrator or the
    rotor, and the filter's error modes after estimate errors."""
    exercise = get("lqg_vs_pid")
    values = exercise.resolve()
    modes = named(exercise, values)
    regulator = [m.label for m in modes if m.set_name == "LQG regulator"]
    assert any("rotor" in name for name in regulator) and any("coil current" in name for name in regulator)
    assert all("estimate error" in m.label for m in modes if m.set_name == "Kalman filter error")


def test_sensor_placement_names_rotor_modes_and_pid():
    exercise = get("sensor_placement")
    labels = [m.label for m in named(exercise, exercise.resolve()) if m.set_name == "closed loop"]
    assert "PID integrator" in labels
    assert any(label.startswith("rotor mode 2 (1st bending)") for label in labels)


def test_marked_mode_is_ringed_and_described():
    exercise = get("kalman_noise")
    values = exercise.resolve()
    view = pole_sets.view(exercise, values, poles_of(exercise, values))
    mode = _mode(exercise, values, "closed loop", "rotor position/velocity (suspension mode)")
    assert pole_map.chosen(view, pole_map.mode_choice(mode)) == mode
    for data, options in pole_map.charts(view, mode):
        ring = [k for k, s in enumerate(options["series"]) if s["label"].startswith(f"mode #{mode.number}:")]
        assert len(ring) == 1
        column = np.asarray(data[ring[0]])
        rows = np.flatnonzero(np.isfinite(column))
        drawn = sorted(complex(data[0][r], column[r]).imag for r in rows)
        assert drawn == pytest.approx(sorted([mode.pole.imag, -mode.pole.imag]))
    text = pole_map.detail_markdown(mode)
    assert "rotor position/velocity (suspension mode)" in text and f"{mode.natural_hz:.4g}" in text
    assert "x [m]" in text and "v [m/s]" in text
