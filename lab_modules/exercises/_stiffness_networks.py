"""The stiffness map of the axial bearing as the exercises build it (paper 002, §C-D): the
least-squares tables of k_i and k_s at the 25 nodes (eq. 26-31) and the fuzzy-basis-function
networks trained on them (eq. 32-33), with the controls they depend on.

stiffness_map identifies and trains them under these controls; adaptive_filter schedules its
filter's k_i and k_s with the networks at the controls' defaults (``NETWORK_DEFAULTS``).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from lab_modules.estimators.fuzzy_basis_network import (
    INITIAL_WIDTH,
    TrainedPair,
    stiffness_networks,
    training_grid,
)
from lab_modules.estimators.stiffness_identification import lsm_factors, lsm_tables
from lab_modules.parameters import Parameter, in_si
from lab_modules.plants.axial_bearing import N_PER_MM

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


def network_key(values: dict) -> tuple:
    """The settings the trained networks depend on."""
    return (values["stencil_current_ma"], values["stencil_position_um"], values["fit"], values["force_noise_n"],
            int(values["seed"]), int(values["fbfnn_epochs"]), values["fbfnn_rate"], values["fbfnn_initial_width"],
            values["fbfnn_train_weights"])


@lru_cache(maxsize=16)
def _networks(key: tuple) -> TrainedPair:
    stencil_ma, stencil_um, fit, noise, seed, epochs, rate, width, train_weights = key
    values = {"stencil_current_ma": stencil_ma, "stencil_position_um": stencil_um, "fit": fit,
              "force_noise_n": noise, "seed": seed}
    ki, ks_mm = identified_tables(values)
    train_i, train_x = training_grid()
    ki_train, ks_train = lsm_factors(train_i, train_x, **lsm_kwargs(values))
    return stiffness_networks(ki, ks_mm * N_PER_MM, ki_train, ks_train, epochs, rate, width, train_weights == "on")


def networks(values: dict) -> TrainedPair:
    """The trained pair for these settings (remembered: training takes about a second)."""
    return _networks(network_key(values))
