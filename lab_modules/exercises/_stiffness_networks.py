"""The stiffness map of the axial bearing as the exercises build it (paper 002, §C-D): the
least-squares tables of k_i and k_s at the 25 nodes (eq. 26-31) and the fuzzy-basis-function
networks trained on them (eq. 32-33), with the controls they depend on.

stiffness_map identifies and trains them under these controls; adaptive_filter schedules its
filter's k_i and k_s with the networks at the controls' defaults (``NETWORK_DEFAULTS``).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.interpolate import RegularGridInterpolator

from lab_modules.estimators.fuzzy_basis_network import (
    INITIAL_WIDTH,
    TrainedPair,
    stiffness_networks,
    test_grid,
    training_grid,
)
from lab_modules.estimators.stiffness_identification import lsm_factors, lsm_tables
from lab_modules.parameters import Parameter, in_si
from lab_modules.plants.axial_bearing import GRID_CURRENTS_A, GRID_POSITIONS_M, N_PER_MM

P = Parameter
FBFNN_EPOCHS = P("fbfnn_epochs", "FBFNN training epochs", "", 1000, 0, 5000,
                 "Steepest-descent steps on the rule widths (Fig. 10).", step=50, integer=True, group="FBFNN")
FBFNN_RATE = P("fbfnn_rate", "FBFNN learning rate", "", 0.1, 1e-3, 1.0,
               "Step of the steepest descent on the relative mean-square error (lab choice).", log=True,
               group="FBFNN")
#: What the tables and the networks depend on, in the order stiffness_map lists them.
NETWORK_CONTROLS = (
    P("fit", "Least-squares model", "", "no_intercept", choices=("no_intercept", "with_intercept"),
      description="no_intercept: F = k_i i + k_s x, the paper's eq. 26; with_intercept: adds a constant "
                  "(tends to the tangent plane).", group="Least squares"),
    P("stencil_current_ma", "Stencil Δi", "mA", 10.0, 0.1, 750.0,
      "Current offsets of the nine samples around each node (eq. 27: 0.01 A).", log=True, group="Least squares"),
    P("stencil_position_um", "Stencil Δx", "µm", 10.0, 0.1, 250.0,
      "Position offsets of the nine samples around each node (eq. 27: 0.01 mm).", log=True,
      group="Least squares"),
    P("force_noise_n", "Force-measurement noise σ_F", "N", 0.0, 0.0, 2.0,
      "White noise on every measured force sample (LSM and ADALINE); the paper's data are noise-free.",
      step=0.01, group="Least squares"),
    FBFNN_EPOCHS,
    FBFNN_RATE,
    P("fbfnn_initial_width", "Initial rule width σ₀", "", INITIAL_WIDTH, 0.1, 2.0,
      "Width of every Gaussian rule before training, in normalised inputs (0.5 = node spacing).",
      step=0.05, group="FBFNN"),
    P("fbfnn_train_weights", "Train the weights too", "", "off", choices=("off", "on"),
      description="off: the weights stay the LSM node values (the paper); on: steepest descent on them too.",
      group="FBFNN"),
)
#: The seed of the force-measurement noise (and of stiffness_map's other noise).
NOISE_SEED = P("seed", "Noise seed", "", 1, 0, 1_000_000, "Seed of the noise generators.", integer=True,
               group="Run")
NETWORK_DEFAULTS = {p.name: p.default for p in (*NETWORK_CONTROLS, NOISE_SEED)}


def lsm_kwargs(values: dict) -> dict:
    """The least-squares settings of the controls in SI units (``lsm_factors``' keywords)."""
    si = in_si(NETWORK_CONTROLS, values)
    return {"stencil_a": si["stencil_current_ma"], "stencil_m": si["stencil_position_um"],
            "intercept": values["fit"] == "with_intercept"}


def identified_tables(values: dict) -> tuple[np.ndarray, np.ndarray]:
    """(k_i [N/A], k_s [N/mm]) on the 5×5 grid (rows x, columns i) with the chosen stencil and noise."""
    rng = np.random.default_rng(int(values["seed"]))
    ki, ks = lsm_tables(force_noise_n=values["force_noise_n"], rng=rng, **lsm_kwargs(values))
    return ki, ks / N_PER_MM


#: What the widths are trained on: the LSM factors of the 20×20 grid (between the nodes too), or the
#: paper's 25 nodes alone (Tables 4-5).
TRAINING_DATA = ("20×20 grid", "25 nodes")
FBFNN_TRAINING = P("fbfnn_training", "FBFNN training data", "", TRAINING_DATA[0], choices=TRAINING_DATA,
                   description="The operating points whose LSM factors train the rule widths: a 20×20 grid "
                               "(between the nodes too) or the paper's 25 nodes.", group="FBFNN")


def network_key(values: dict) -> tuple:
    """The settings the trained networks depend on."""
    return (values["stencil_current_ma"], values["stencil_position_um"], values["fit"], values["force_noise_n"],
            int(values["seed"]), int(values["fbfnn_epochs"]), values["fbfnn_rate"], values["fbfnn_initial_width"],
            values["fbfnn_train_weights"], values.get("fbfnn_training", TRAINING_DATA[0]))


def node_points() -> tuple[np.ndarray, np.ndarray]:
    """The 25 nodes (i [A], x [m]) in the tables' order (rows x, columns i)."""
    currents, positions = np.meshgrid(GRID_CURRENTS_A, GRID_POSITIONS_M, indexing="xy")
    return currents.ravel(), positions.ravel()


def _least_squares_values(key: tuple) -> dict:
    """The least-squares settings (controls' names and values) of a ``network_key``."""
    stencil_ma, stencil_um, fit, noise, seed = key[:5]
    return {"stencil_current_ma": stencil_ma, "stencil_position_um": stencil_um, "fit": fit,
            "force_noise_n": noise, "seed": seed}


@lru_cache(maxsize=16)
def _networks(key: tuple) -> TrainedPair:
    epochs, rate, width, train_weights, training = key[5:]
    values = _least_squares_values(key)
    ki, ks_mm = identified_tables(values)
    if training == TRAINING_DATA[1]:           # the nodes: their (noisy) table values are the targets
        inputs, ki_train, ks_train = node_points(), ki.ravel(), ks_mm.ravel() * N_PER_MM
    else:
        inputs = training_grid()
        ki_train, ks_train = lsm_factors(*inputs, **lsm_kwargs(values))
    return stiffness_networks(ki, ks_mm * N_PER_MM, ki_train, ks_train, epochs, rate, width, train_weights == "on",
                              inputs)


def map_test_rmse(pair: TrainedPair, values: dict) -> dict[str, dict[str, float]]:
    """Test RMSE on the 41×41 grid against the exact LSM factors, k_i [N/A] and k_s [N/mm]: the trained
    networks and a bilinear table of the 25 nodes (the interpolation a table-lookup filter would use)."""
    currents, positions = test_grid()
    ki_true, ks_true = lsm_factors(currents, positions, **lsm_kwargs(values))
    ki_table, ks_table = identified_tables(values)
    out = {}
    for name, network, table, truth, unit in (("k_i", pair.ki, ki_table, ki_true, 1.0),
                                              ("k_s", pair.ks, ks_table, ks_true, N_PER_MM)):
        bilinear = RegularGridInterpolator((GRID_POSITIONS_M, GRID_CURRENTS_A), table)   # rows x, columns i
        table_error = bilinear(np.column_stack([positions, currents])) * unit - truth     # tables in N/mm
        out[name] = {"fbfnn": network.rmse(currents, positions, truth) / unit,
                     "bilinear": float(np.sqrt(np.mean(table_error**2))) / unit}
    return out


def networks(values: dict) -> TrainedPair:
    """The trained pair for these settings (remembered: training takes about a second)."""
    return _networks(network_key(values))


@lru_cache(maxsize=16)
def _network_test_rmse(key: tuple) -> dict[str, dict[str, float]]:
    return map_test_rmse(_networks(key), _least_squares_values(key))


def network_test_rmse(values: dict) -> dict[str, dict[str, float]]:
    """``map_test_rmse`` of the trained pair for these settings (remembered with it: the 41×41 grid's
    exact factors and the bilinear table cost more than reading them)."""
    return {name: dict(found) for name, found in _network_test_rmse(network_key(values)).items()}
