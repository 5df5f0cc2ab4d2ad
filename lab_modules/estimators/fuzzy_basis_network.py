"""Fuzzy-basis-function neural network (FBFNN) that maps an operating point
(i, x) to a stiffness factor (paper 002, §D, eq. 32-33, Figs. 9-10).

Layer 1 takes the normalised inputs u = (i / 1.5 A, x / 0.5 mm).  Layer 2 has one
Gaussian rule per node of the 5×5 grid (Tables 2-3), μ_r = exp(-‖u - c_r‖² / σ_r²)
(eq. 32).  Layer 3 is the fuzzy-basis-function output

    y = Σ_r w_r μ_r / Σ_r μ_r                                   (eq. 33, reconstructed)

whose weights w_r are the LSM factors at the nodes ("the consequent parameters
w_i ... are from the process of parameter identification").  The paper trains the
widths σ_r by steepest descent (Fig. 10); the lab does the same on the relative
mean-square error (MSE divided by the variance of the targets, so one learning
rate serves k_i and k_s), optionally the weights too.  The sum in eq. 33 did not
survive the text; the normalised form is the standard fuzzy basis function
(Wang & Mendel) and makes the network return w_r exactly at its node when the
rules are narrow.

Training data must lie between the nodes too: on the 25 nodes alone the error
vanishes as σ → 0 (each node is then its own rule) and the map between nodes
becomes a staircase.  The lab trains on the LSM factors of a 20×20 grid and tests
on a 41×41 grid.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import NamedTuple

import numpy as np
from numba import njit

from lab_modules.plants.axial_bearing import GRID_CURRENTS_A, GRID_POSITIONS_M

CURRENT_SCALE_A = 1.5
POSITION_SCALE_M = 0.5e-3
#: Initial width: the node spacing in normalised inputs (0.5), the usual start.
INITIAL_WIDTH = 0.5
MIN_WIDTH, MAX_WIDTH = 0.05, 3.0


def _node_centres() -> np.ndarray:
    currents, positions = np.meshgrid(GRID_CURRENTS_A / CURRENT_SCALE_A, GRID_POSITIONS_M / POSITION_SCALE_M,
                                      indexing="xy")
    return np.stack([currents.ravel(), positions.ravel()], axis=1)   # row-major: rows x, columns i


CENTRES = _node_centres()


def normalise(current_a, position_m) -> np.ndarray:
    """Network inputs (..., 2) of operating points in A and m."""
    i, x = np.broadcast_arrays(np.asarray(current_a, float), np.asarray(position_m, float))
    return np.stack([i / CURRENT_SCALE_A, x / POSITION_SCALE_M], axis=-1)


def distances(inputs: np.ndarray) -> np.ndarray:
    """Squared distances ‖u - c_r‖² (n, 25) of normalised inputs (n, 2) to the rule centres."""
    return np.sum((inputs[:, None, :] - CENTRES[None]) ** 2, axis=-1)


class MembershipLayout(NamedTuple):
    """Training inputs laid out for ``train_widths``: eq. 32 factorises along the two normalised
    axes, μ_r = exp(-(u_i - c_r,i)² / σ_r²) · exp(-(u_x - c_r,x)² / σ_r²), and a grid of n × n points
    has only n distinct values per axis, so each epoch takes 2 n exponentials per rule instead of n²."""

    current_offsets2: np.ndarray    # (25, J) (u_i - c_r,i)² of the J distinct normalised currents [-]
    position_offsets2: np.ndarray   # (25, K) (u_x - c_r,x)² of the K distinct normalised positions [-]
    current_index: np.ndarray       # (n,) each training point's distinct current (column of current_offsets2)
    position_index: np.ndarray      # (n,) each training point's distinct position (column of position_offsets2)


def membership_layout(current_a, position_m) -> MembershipLayout:
    """``MembershipLayout`` of the operating points (i [A], x [m])."""
    inputs = normalise(current_a, position_m).reshape(-1, 2)
    currents, current_index = np.unique(inputs[:, 0], return_inverse=True)
    positions, position_index = np.unique(inputs[:, 1], return_inverse=True)
    return MembershipLayout((currents[None] - CENTRES[:, 0, None]) ** 2, (positions[None] - CENTRES[:, 1, None]) ** 2,
                            current_index.ravel(), position_index.ravel())


@njit(cache=True, nogil=True)
def train_widths(layout, target, weights, widths, epochs, rate, train_weights, scale):
    """``epochs`` steps of batch steepest descent on the relative MSE (MSE / ``scale``, the targets'
    variance) of eq. 33 at the points of ``layout``; ``widths`` and (if ``train_weights``) ``weights``
    in place.  Returns the training RMSE per epoch (before each step), in the targets' unit.  The
    compiled form of ``FuzzyBasisNetwork.train_at`` (its twin: same steps, float order aside)."""
    rules, points = weights.size, target.size
    across = np.empty((rules, layout.current_offsets2.shape[1]))
    along = np.empty((rules, layout.position_offsets2.shape[1]))
    phi, grad_sigma, grad_w = np.empty(rules), np.empty(rules), np.empty(rules)
    history = np.empty(epochs)
    for epoch in range(epochs):
        for r in range(rules):
            width2 = widths[r] ** 2
            for j in range(across.shape[1]):
                across[r, j] = np.exp(-layout.current_offsets2[r, j] / width2)    # eq. 32, current factor
            for j in range(along.shape[1]):
                along[r, j] = np.exp(-layout.position_offsets2[r, j] / width2)    # eq. 32, position factor
            grad_sigma[r] = 0.0
            grad_w[r] = 0.0
        squares = 0.0
        for n in range(points):
            ic, ip = layout.current_index[n], layout.position_index[n]
            total = 0.0
            for r in range(rules):
                phi[r] = across[r, ic] * along[r, ip]
                total += phi[r]
            normalising = 1.0 / max(total, 1e-300)
            y = 0.0
            for r in range(rules):
                phi[r] *= normalising                                          # φ_r = μ_r / Σ μ
                y += phi[r] * weights[r]                                       # eq. 33
            error = y - target[n]
            squares += error * error
            for r in range(rules):
                # ∂y/∂σ_r = φ_r (w_r - y) · 2 d²_r / σ_r³ (the factor 2 / σ_r³ after the sum) ;  ∂y/∂w_r = φ_r
                d2 = layout.current_offsets2[r, ic] + layout.position_offsets2[r, ip]
                grad_sigma[r] += error * phi[r] * (weights[r] - y) * d2
                grad_w[r] += error * phi[r]
        history[epoch] = np.sqrt(squares / points)
        for r in range(rules):
            step = widths[r] - rate * (2.0 * grad_sigma[r] * (2.0 / widths[r] ** 3) / (points * scale))
            if train_weights:
                weights[r] -= rate * (2.0 * grad_w[r] / (points * scale)) * scale
            widths[r] = min(max(step, MIN_WIDTH), MAX_WIDTH)                   # clip
    return history


@dataclass
class FuzzyBasisNetwork:
    """One output (k_i or k_s); ``weights`` in the output's unit."""

    weights: np.ndarray                                   # (25,) rule consequents
    widths: np.ndarray = field(default_factory=lambda: np.full(25, INITIAL_WIDTH))

    @classmethod
    def from_table(cls, table: np.ndarray, width: float = INITIAL_WIDTH) -> FuzzyBasisNetwork:
        """Rules from a 5×5 table (rows x, columns i), all widths ``width``."""
        return cls(np.asarray(table, float).ravel().copy(), np.full(25, float(width)))

    def _basis(self, minus_d2: np.ndarray) -> np.ndarray:
        """The normalised rule activations φ_r (eq. 32-33) at inputs with squared distances d² to the
        centres (``distances``), given as ``minus_d2`` = −d²."""
        mu = np.exp(minus_d2 / self.widths[None] ** 2)
        total = np.sum(mu, axis=1, keepdims=True)
        return mu / np.maximum(total, 1e-300)

    def predict(self, current_a, position_m) -> np.ndarray:
        inputs = normalise(current_a, position_m)
        return self.predict_at(distances(inputs.reshape(-1, 2))).reshape(inputs.shape[:-1])

    def predict_at(self, d2: np.ndarray) -> np.ndarray:
        """Eq. 33 at inputs given by their squared distances d² (n, 25) to the centres (``distances``)."""
        return self._basis(-d2) @ self.weights

    def rmse(self, current_a, position_m, target) -> float:
        return float(np.sqrt(np.mean((self.predict(current_a, position_m) - np.asarray(target)) ** 2)))

    def rmse_at(self, d2: np.ndarray, target) -> float:
        """``rmse`` at inputs given by their squared distances d² to the centres (``grid_distances``)."""
        return float(np.sqrt(np.mean((self.predict_at(d2) - np.asarray(target)) ** 2)))

    def train(self, current_a, position_m, target, epochs: int, rate: float,
              train_weights: bool = False) -> list[float]:
        """Steepest descent (batch) on the relative MSE; returns the training RMSE per epoch.  The slow,
        obvious twin of ``train_on`` (numpy, one epoch at a time)."""
        return self.train_at(distances(normalise(current_a, position_m).reshape(-1, 2)), target, epochs, rate,
                             train_weights)

    def train_at(self, d2: np.ndarray, target, epochs: int, rate: float, train_weights: bool = False) -> list[float]:
        """``train`` on inputs given by their squared distances d² (n, 25) to the centres."""
        minus_d2, twice_d2 = -d2, 2.0 * d2
        target = np.asarray(target, float).ravel()
        scale = max(float(np.var(target)), 1e-300)
        history = []
        for _ in range(int(epochs)):
            phi = self._basis(minus_d2)
            y = phi @ self.weights
            error = y - target
            history.append(float(np.sqrt(np.mean(error**2))))
            # ∂y/∂σ_r = φ_r (w_r - y) · 2 d²_r / σ_r³ ;  ∂y/∂w_r = φ_r
            dy_dsigma = phi * (self.weights[None] - y[:, None]) * (twice_d2 / self.widths[None] ** 3)
            grad_sigma = 2.0 * (error @ dy_dsigma) / (error.size * scale)
            if train_weights:
                grad_w = 2.0 * (error @ phi) / (error.size * scale)
                self.weights = self.weights - rate * grad_w * scale
            self.widths = np.minimum(np.maximum(self.widths - rate * grad_sigma, MIN_WIDTH), MAX_WIDTH)   # clip
        return history

    def train_on(self, layout: MembershipLayout, target, epochs: int, rate: float,
                 train_weights: bool = False) -> list[float]:
        """``train`` at the points of ``layout`` (``membership_layout``), compiled (``train_widths``)."""
        target = np.ascontiguousarray(target, float).ravel()
        self.weights, self.widths = self.weights.astype(float), self.widths.astype(float)   # fresh: trained in place
        history = train_widths(layout, target, self.weights, self.widths, int(epochs), float(rate),
                               bool(train_weights), max(float(np.var(target)), 1e-300))
        return history.tolist()

    def copy(self) -> FuzzyBasisNetwork:
        return FuzzyBasisNetwork(self.weights.copy(), self.widths.copy())


def training_grid(n: int = 20) -> tuple[np.ndarray, np.ndarray]:
    """Operating points (i [A], x [m]) of an n×n grid over the identified range."""
    currents, positions = np.meshgrid(np.linspace(-1.5, 1.5, n), np.linspace(-0.5e-3, 0.5e-3, n), indexing="xy")
    return currents.ravel(), positions.ravel()


@njit(cache=True, nogil=True)
def evaluate(current_a, position_m, centres, weights, widths):
    """Eq. 32-33 at one operating point (for the compiled loop)."""
    u0 = current_a / CURRENT_SCALE_A
    u1 = position_m / POSITION_SCALE_M
    num = 0.0
    den = 0.0
    for r in range(weights.size):
        d2 = (u0 - centres[r, 0]) ** 2 + (u1 - centres[r, 1]) ** 2
        mu = np.exp(-d2 / widths[r] ** 2)
        num += weights[r] * mu
        den += mu
    if den <= 1e-300:
        return 0.0
    return num / den


TEST_POINTS = 41           # the test grid: 41 × 41 operating points
TRAINING_POINTS = 20       # the training grid: 20 × 20 (between and on the nodes)


def test_grid(n: int = TEST_POINTS) -> tuple[np.ndarray, np.ndarray]:
    return training_grid(n)


@lru_cache(maxsize=4)
def grid_distances(n: int) -> np.ndarray:
    """``distances`` (n², 25) of the n×n grid's operating points (``training_grid``), read-only: the
    live view trains and tests on the same grids at every frame, so they are computed once."""
    currents, positions = training_grid(n)
    d2 = distances(normalise(currents, positions).reshape(-1, 2))
    d2.flags.writeable = False
    return d2


@lru_cache(maxsize=4)
def grid_layout(n: int) -> MembershipLayout:
    """``membership_layout`` of the n×n grid (``training_grid``), computed once (the live view trains
    on it at every frame)."""
    return membership_layout(*training_grid(n))


@dataclass
class TrainedPair:
    """The two networks (k_i [N/A], k_s [N/m]) and their RMSE histories."""

    ki: FuzzyBasisNetwork
    ks: FuzzyBasisNetwork
    ki_untrained: FuzzyBasisNetwork
    ks_untrained: FuzzyBasisNetwork
    ki_history: list[float]
    ks_history: list[float]


def stiffness_networks(ki_table: np.ndarray, ks_table: np.ndarray, ki_train: np.ndarray, ks_train: np.ndarray,
                       epochs: int, rate: float, initial_width: float = INITIAL_WIDTH,
                       train_weights: bool = False, inputs: tuple | None = None) -> TrainedPair:
    """Networks from the node tables, widths trained on the LSM factors ``*_train`` at the operating
    points ``inputs`` (i [A], x [m]); None: ``training_grid()`` (``epochs`` steps of steepest descent)."""
    currents, positions = training_grid() if inputs is None else inputs
    ki = FuzzyBasisNetwork.from_table(ki_table, initial_width)
    ks = FuzzyBasisNetwork.from_table(ks_table, initial_width)
    before = (ki.copy(), ks.copy())
    layout = membership_layout(currents, positions)
    ki_history = ki.train_on(layout, ki_train, epochs, rate, train_weights)
    ks_history = ks.train_on(layout, ks_train, epochs, rate, train_weights)
    return TrainedPair(ki, ks, *before, ki_history, ks_history)


class LiveTraining:
    """Both networks trained epoch by epoch, as the live view does it.

    Batch steepest descent is deterministic: two ``LiveTraining`` of the same
    tables and training data hold the same networks at the same epoch, so a 3D
    view can follow a running training by replaying it (``advance_to``)."""

    def __init__(self, ki_table: np.ndarray, ks_table: np.ndarray, ki_train: np.ndarray, ks_train: np.ndarray,
                 rate: float, initial_width: float = INITIAL_WIDTH, train_weights: bool = False):
        self.tables = (np.asarray(ki_table, float), np.asarray(ks_table, float))
        self.targets = (np.asarray(ki_train, float), np.asarray(ks_train, float))
        self.rate, self.initial_width, self.train_weights = rate, initial_width, train_weights
        self.restart()

    def restart(self) -> None:
        self.ki = FuzzyBasisNetwork.from_table(self.tables[0], self.initial_width)
        self.ks = FuzzyBasisNetwork.from_table(self.tables[1], self.initial_width)
        self.epoch = 0

    def train(self, epochs: int) -> None:
        """``epochs`` more steps of steepest descent on both networks."""
        if epochs <= 0:
            return
        layout = grid_layout(TRAINING_POINTS)
        self.ki.train_on(layout, self.targets[0], epochs, self.rate, self.train_weights)
        self.ks.train_on(layout, self.targets[1], epochs, self.rate, self.train_weights)
        self.epoch += int(epochs)

    def advance_to(self, epoch: int) -> None:
        """The networks after ``epoch`` epochs (from the start again if ``epoch`` lies behind)."""
        epoch = int(epoch)
        if epoch < self.epoch:
            self.restart()
        self.train(epoch - self.epoch)
