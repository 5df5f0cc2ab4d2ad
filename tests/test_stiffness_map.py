"""Exercise ``stiffness_map`` (paper 002): the force law, the no-intercept least
squares of Tables 4-5, the FBFNN and the ADALINE, and the paper's claims."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lab_modules.estimators.adaline import siso_step
from lab_modules.estimators.fuzzy_basis_network import (
    CENTRES,
    FuzzyBasisNetwork,
    evaluate,
    grid_distances,
    grid_layout,
    membership_layout,
    test_grid,
    training_grid,
)
from lab_modules.estimators.stiffness_identification import lsm_factors, lsm_factors_at
from lab_modules.exercises.stiffness_map import EXERCISE
from lab_modules.plants.axial_bearing import AXIAL, TABLE_4_KI_N_PER_A, TABLE_5_KS_N_PER_MM

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def metrics():
    return EXERCISE.metrics(EXERCISE.resolve({}), EXERCISE.default_duration_s)


@pytest.mark.parametrize("claim", EXERCISE.claims, ids=lambda c: c.metric)
def test_claim_holds_at_the_defaults(claim, metrics):
    assert not claim.settings
    value = claim.value_in(metrics)
    assert claim.holds(value), f"{claim.quantity}: {value} not in {claim.accept_text()}"


def test_tangent_factors_are_the_derivatives_of_the_force_law():
    i, x, h = 0.37, -0.21e-3, 1e-7
    k_i, k_s = AXIAL.tangent_factors(i, x)
    assert k_i == pytest.approx((AXIAL.force_n(i + h, x) - AXIAL.force_n(i - h, x)) / (2 * h), rel=1e-6)
    assert k_s == pytest.approx((AXIAL.force_n(i, x + h * 1e-3) - AXIAL.force_n(i, x - h * 1e-3)) / (2e-3 * h),
                                rel=1e-6)
    assert AXIAL.centre_factors() == pytest.approx((10.05, 7537.5))


def test_least_squares_agrees_with_numpy_lstsq():
    """The no-intercept fit (eq. 31) against numpy's solver, and the compiled closed form."""
    i, x, d_i, d_x = 0.9, 0.31e-3, 0.02, 0.015e-3
    di, dx = np.meshgrid([-d_i, 0, d_i], [-d_x, 0, d_x], indexing="ij")
    A = np.column_stack([i + di.ravel(), x + dx.ravel()])
    theta, *_ = np.linalg.lstsq(A, AXIAL.force_n(A[:, 0], A[:, 1]), rcond=None)
    assert lsm_factors(i, x, d_i, d_x) == pytest.approx(tuple(theta), rel=1e-9)
    assert lsm_factors_at(i, x, d_i, d_x, AXIAL.k_magnet_n_m2_per_a2, AXIAL.nominal_gap_m,
                          AXIAL.bias_current_a) == pytest.approx(tuple(theta), rel=1e-9)


def test_with_a_constant_the_fit_tends_to_the_tangent_but_without_it_does_not():
    i, x = -1.5, -0.5e-3
    tangent = AXIAL.tangent_factors(i, x)
    assert lsm_factors(i, x, 1e-4, 1e-7, intercept=True) == pytest.approx(tangent, rel=1e-4)
    k_i, _ = lsm_factors(i, x, 1e-4, 1e-7)
    assert k_i < 0.5 * tangent[0]


def test_the_identified_map_has_the_bearings_symmetry(metrics):
    """F(-i, -x) = -F(i, x): the tables are point-symmetric; the paper's one asymmetric entry is the misprint."""
    ki, ks = np.array(metrics["lsm_ki_table_n_per_a"]), np.array(metrics["lsm_ks_table_n_per_mm"])
    assert np.allclose(ki, ki[::-1, ::-1], atol=1e-9) and np.allclose(ks, ks[::-1, ::-1], atol=1e-8)
    asymmetric = np.argwhere(np.abs(TABLE_4_KI_N_PER_A - TABLE_4_KI_N_PER_A[::-1, ::-1]) > 0.011)
    assert {tuple(a) for a in asymmetric} == {(0, 1), (4, 3)}
    assert np.max(np.abs(TABLE_5_KS_N_PER_MM - TABLE_5_KS_N_PER_MM[::-1, ::-1])) <= 0.011


def test_noise_makes_small_stencils_worse():
    rng = np.random.default_rng(3)
    errors = []
    for d in (1e-3, 0.1):
        k_i, _ = lsm_factors(np.full(300, 0.75), np.full(300, 0.25e-3), d, d * 1e-3, 0.05, rng)
        errors.append(np.std(k_i))
    assert errors[0] > 10 * errors[1]


def test_fbfnn_width_gradient_matches_finite_differences():
    rng = np.random.default_rng(0)
    net = FuzzyBasisNetwork(rng.uniform(5, 15, 25), rng.uniform(0.3, 0.8, 25))
    i, x = rng.uniform(-1.5, 1.5, 60), rng.uniform(-0.5e-3, 0.5e-3, 60)
    target = 10 + np.sin(i) + 2e3 * x

    def loss(widths):
        return np.mean((FuzzyBasisNetwork(net.weights, widths).predict(i, x) - target) ** 2) / np.var(target)

    rate = 1e-3
    trained = net.copy()
    trained.train(i, x, target, 1, rate)
    step = (net.widths - trained.widths) / rate            # the gradient the training used
    numeric = np.array([(loss(net.widths + 1e-6 * e) - loss(net.widths - 1e-6 * e)) / 2e-6 for e in np.eye(25)])
    assert step == pytest.approx(numeric, rel=1e-4, abs=1e-9)


def test_narrow_rules_return_the_node_values_and_compiled_evaluation_agrees():
    weights = np.arange(25, dtype=float)
    net = FuzzyBasisNetwork(weights, np.full(25, 0.05))
    i, x = CENTRES[:, 0] * 1.5, CENTRES[:, 1] * 0.5e-3
    assert net.predict(i, x) == pytest.approx(weights, abs=1e-9)
    wide = FuzzyBasisNetwork(weights, np.full(25, 0.7))
    assert evaluate(0.3, -0.1e-3, CENTRES, weights, wide.widths) == pytest.approx(float(wide.predict(0.3, -0.1e-3)))


def test_adaline_learns_nothing_without_a_regressor_and_converges_with_one():
    assert siso_step(5.0, 0.0, 0.3, 0.5) == 5.0
    w, phi, rate = 5.0, 0.76, 0.0175
    for _ in range(500):
        w = siso_step(w, phi, 6.7 * phi, rate)
    assert 6.7 - w == pytest.approx(1.7 * (1 - rate * phi**2) ** 500, rel=1e-9)   # LMS: geometric convergence


def run_app(*argv):
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return subprocess.run([sys.executable, "-m", "app", *argv], check=False, cwd=REPO, env=env,
                          capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("setting, tokens", [
    ("stencil_current_ma=0", ["stencil_current_ma", "0.1", "750"]),
    ("node_current_a=2", ["node_current_a", "-1.5", "1.5"]),
    ("fbfnn_epochs=12.5", ["fbfnn_epochs", "5000"]),
])
def test_cli_bad_input_exits_2_with_one_line(setting, tokens):
    result = run_app("run", "stiffness_map", "--set", setting, "--json")
    assert result.returncode == 2
    assert result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1
    assert all(token in lines[0] for token in tokens), lines[0]


def test_the_live_view_on_its_fixed_grids_computes_what_the_network_computes_from_the_inputs():
    """The live view trains and tests on distances computed once per grid (``grid_distances``):
    the same numbers, digit for digit, as from the operating points every time."""
    rng = np.random.default_rng(5)
    tables = TABLE_4_KI_N_PER_A, TABLE_5_KS_N_PER_MM
    for table, n in zip(tables, (41, 20)):
        currents, positions = test_grid(n)
        target = rng.normal(table.mean(), table.std(), currents.size)
        net = FuzzyBasisNetwork.from_table(table, 0.3)
        assert net.rmse_at(grid_distances(n), target) == net.rmse(currents, positions, target)
        assert np.array_equal(net.predict_at(grid_distances(n)), net.predict(currents, positions))
    currents, positions = training_grid()
    target = rng.normal(20.0, 2.0, currents.size)
    by_points, by_distances = (FuzzyBasisNetwork.from_table(TABLE_4_KI_N_PER_A) for _ in range(2))
    assert by_points.train(currents, positions, target, 3, 0.1) == by_distances.train_at(grid_distances(20), target,
                                                                                         3, 0.1)
    assert np.array_equal(by_points.widths, by_distances.widths)
    assert not grid_distances(20).flags.writeable


@pytest.mark.parametrize("points, train_weights", [("grid", False), ("grid", True), ("nodes", False), ("scattered", True)])
def test_compiled_training_follows_its_numpy_twin(points, train_weights):
    """``train_on`` (compiled, eq. 32 factorised along the axes) takes the steps ``train`` takes: the same
    widths, weights and RMSE history up to the float order (1e-9 relative over 300 epochs)."""
    rng = np.random.default_rng(11)
    if points == "grid":
        currents, positions = training_grid()
    elif points == "nodes":
        currents, positions = CENTRES[:, 0] * 1.5, CENTRES[:, 1] * 0.5e-3
    else:                                               # no two points share an axis value: no saving, same result
        currents, positions = rng.uniform(-1.5, 1.5, 90), rng.uniform(-0.5e-3, 0.5e-3, 90)
    target = lsm_factors(currents, positions)[0] + rng.normal(0.0, 0.5, currents.size)
    twin, compiled = (FuzzyBasisNetwork.from_table(TABLE_4_KI_N_PER_A, 0.4) for _ in range(2))
    expected = twin.train(currents, positions, target, 300, 0.1, train_weights)
    history = compiled.train_on(membership_layout(currents, positions), target, 300, 0.1, train_weights)
    assert not np.array_equal(twin.widths, FuzzyBasisNetwork.from_table(TABLE_4_KI_N_PER_A, 0.4).widths)
    assert history == pytest.approx(expected, rel=1e-9)
    assert compiled.widths == pytest.approx(twin.widths, rel=1e-9)
    assert compiled.weights == pytest.approx(twin.weights, rel=1e-9)


def test_membership_layout_holds_the_squared_distances_to_the_centres():
    layout = grid_layout(20)
    d2 = (layout.current_offsets2[:, layout.current_index] + layout.position_offsets2[:, layout.position_index]).T
    assert np.array_equal(d2, grid_distances(20))
    assert layout.current_offsets2.shape == layout.position_offsets2.shape == (25, 20)
