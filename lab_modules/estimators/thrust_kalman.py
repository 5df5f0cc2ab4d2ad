"""The Kalman filter of paper 003 (eq. 12-18) on the thrust bearing's fixed linearisation.

The paper calls it an extended Kalman filter, but its Φ, B_d and G_d (eq. 9-11)
are constant matrices of the model linearised once at (i0, x0) (eq. 4): with
no re-linearisation along the estimate it is a linear Kalman filter.  It runs
on the compiled kernels of ``estimators.kalman`` (padded to their four states).

Eq. 17 as printed corrects the *previous* estimate,
x̂_k = x̂_{k-1} + K_k (z_k − H x̂_{k-1}), which throws the prediction of
eq. 14 (and with it the measured current) away; the lab uses the standard
form x̂_k = x̂_{k,k-1} + K_k (z_k − H x̂_{k,k-1}).

Tuning (§3 gives only X0 and P0): the printed P0 is rank one and equals
G_d Q G_d^T for Q ≈ 2.64e6 N² (``process_noise_from_p0``), so the lab reads
it as one step of the process noise of eq. 15 and uses that Q; R = σ_v²
(the sensor noise variance) times a factor the student can change.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property, lru_cache

import numpy as np
import scipy.linalg

from lab_modules.estimators.kalman import KalmanFilter
from lab_modules.plants.thrust_bearing import PAPER_P0, TABLE_1, ThrustBearing

H = np.array([[1.0, 0.0]])          # eq. 13: Z_k = x_k + V_k


def process_noise_from_p0(bearing: ThrustBearing = TABLE_1, P0: np.ndarray = PAPER_P0) -> float:
    """Q [N²] with G_d Q G_d^T closest to P0 (least squares over its three entries)."""
    _, _, G_d = bearing.taylor_discretisation()
    outer = np.outer(G_d, G_d)
    return float(np.sum(outer * P0) / np.sum(outer * outer))


#: Q read from the printed P0: 2.64e6 N² (a force of about 1.6 kN per 0.1 ms step).
PAPER_Q_N2 = process_noise_from_p0()


@dataclass(frozen=True)
class ThrustFilterDesign:
    """The filter of eq. 14-18: Taylor model (eq. 9-11), Q [N²] on f_dis, R [m²] on z;
    ``exact_model``: the exact ZOH matrices e^{AT}, ∫e^{At}dt B instead (the plant's own)."""

    process_noise_n2: float = PAPER_Q_N2
    measurement_variance_m2: float = (5e-6) ** 2
    bearing: ThrustBearing = TABLE_1
    exact_model: bool = False

    @cached_property
    def matrices(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(Φ, B_d, Q_d = G_d Q G_d^T) of eq. 9-11, 15 (or of the exact discretisation)."""
        Phi, B_d, G_d = (self.bearing.exact_discretisation() if self.exact_model
                         else self.bearing.taylor_discretisation())
        return Phi, B_d, self.process_noise_n2 * np.outer(G_d, G_d)

    def filter(self, x0=(-0.75e-3, 0.0), P0=PAPER_P0) -> KalmanFilter:
        """A fresh filter at the paper's X0 = [−0.75 mm, 0] and P0 (§3)."""
        Phi, B_d, Q_d = self.matrices
        return KalmanFilter(Phi, B_d, H, Q_d, [self.measurement_variance_m2], x0, P0)

    @property
    def steady_state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(K∞ (2,), predicted P∞, corrected P∞) from the discrete Riccati equation (scipy)."""
        return tuple(M.copy() for M in _steady_state(self))

    def error_poles(self) -> np.ndarray:
        """z-plane poles of the estimation error, eig((I − K∞ H) Φ)."""
        gain, _, _ = self.steady_state
        Phi, _, _ = self.matrices
        return np.linalg.eigvals((np.eye(2) - np.outer(gain, H)) @ Phi)

    def gain_history(self, n_steps: int, P0=PAPER_P0) -> tuple[np.ndarray, np.ndarray]:
        """K_k (n, 2) and corrected P_k (n, 2, 2) from P0 (eq. 15, 16, 18): they do not
        depend on the data, only on the model and the noise variances."""
        Phi, _, Q_d = self.matrices
        R = self.measurement_variance_m2
        P = np.array(P0, dtype=float)
        gains, covariances = np.empty((n_steps, 2)), np.empty((n_steps, 2, 2))
        for k in range(n_steps):
            if k:
                P = Phi @ P @ Phi.T + Q_d
            s = P[0, 0] + R
            K = P[:, 0] / s
            M = np.eye(2) - np.outer(K, H)
            P = M @ P @ M.T + R * np.outer(K, K)
            gains[k], covariances[k] = K, P
        return gains, covariances


@lru_cache(maxsize=256)
def _steady_state(design: ThrustFilterDesign):
    Phi, _, Q_d = design.matrices
    R = max(design.measurement_variance_m2, 1e-30)
    P_pred = scipy.linalg.solve_discrete_are(Phi.T, H.T, Q_d, np.array([[R]]))
    gain = (P_pred @ H.T / (H @ P_pred @ H.T + R)).ravel()
    P_corr = (np.eye(2) - np.outer(gain, H)) @ P_pred
    return gain, P_pred, P_corr
