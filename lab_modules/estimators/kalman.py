"""Linear Kalman filter of paper 000, eq. 2, for the simulation loop.

The filter works in place on small arrays so that the compiled closed loops
(e.g. ``lab_modules.loops.radial_axis_loop``) can call it 20 000 times per simulated second
without allocating.  ``KalmanFilter`` wraps the same two kernels for step-by-
step use (tests, notebooks); there is one implementation.

Prediction step (eq. 2)::

    x_{k|k-1} = A x_{k-1|k-1} + B u_{k-1}
    P_{k|k-1} = A P_{k-1|k-1} A^T + Q

Correction step (eq. 2), with a diagonal R (as eq. 16) the measurements are
processed one scalar at a time, which is exactly equivalent and needs no
matrix inverse.  For each row c of C with variance r::

    s = c P c^T + r,   K = P c^T / s
    x = x + K (y - c x)
    P = (I - K c) P (I - K c)^T + r K K^T      (Joseph form: P stays symmetric PSD)
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

_JIT = {"nogil": True, "cache": True, "fastmath": True}


#: The linear filter's kernels work on exactly this many states.  Smaller
#: models are padded with decoupled states whose rows of P stay zero;
#: ``KalmanFilter`` does the padding.
STATE_SIZE = 4


# The kernels below serve any number of states ``n_states``; the extended
# filters (``extended_kalman``, 5 states; ``continuous_discrete_ekf``, 3)
# share them.  Numba inlines them into each compiled caller
# (``inline="always"``), so the caller's constant (``STATE_SIZE``, ...) fixes the loop lengths at compile time and the
# compiler unrolls them (about 2x faster than loops of run-time length).

@numba.njit(inline="always", **_JIT)
def propagate_covariance(P, A, Q, work_P, n_states):
    """P <- A P A^T + Q in place (eq. 2; eq. 6 with A = Phi), exactly symmetric."""
    n = n_states
    for r in range(n):
        for c in range(n):
            work_P[r, c] = 0.0
        for k in range(n):
            a_rk = A[r, k]
            for c in range(n):
                work_P[r, c] += a_rk * P[k, c]          # work_P = A P
    for r in range(n):                                   # P = (A P) A^T + Q, upper half
        for c in range(r, n):
            acc = Q[r, c]
            for k in range(n):
                acc += work_P[r, k] * A[c, k]
            P[r, c] = acc
            P[c, r] = acc                                # exact symmetry


@numba.njit(**_JIT)
def predict(x, P, A, B, u, Q, work_x, work_P):
    """Eq. 2, prediction: x <- A x + B u,  P <- A P A^T + Q (in place, ``STATE_SIZE`` states)."""
    n = STATE_SIZE
    for r in range(n):
        work_x[r] = B[r] * u
    for c in range(n):
        for r in range(n):
            work_x[r] += A[r, c] * x[c]
    for r in range(n):
        x[r] = work_x[r]
    propagate_covariance(P, A, Q, work_P, STATE_SIZE)


@numba.njit(inline="always", **_JIT)
def update_scalar(x, P, c_row, y, r, gain, n_states):
    """Eq. 2 (and eq. 6), correction with one scalar measurement y = c x + eta, var(eta) = r.

    Joseph form P = M P M^T + r K K^T with M = I - K c.  Because M is the
    identity minus a rank-one matrix, both products cost O(n^2):
    M P = P - K a^T with a = P c^T = s K, and (M P) M^T = W - (W c^T) K^T
    with W c^T = a - K (c P c^T).
    Writes the Kalman gain into ``gain``; returns the innovation and its variance."""
    n = n_states
    innovation = y
    for i in range(n):
        innovation -= c_row[i] * x[i]
        gain[i] = 0.0
    for j in range(n):                       # a = P c^T (P symmetric)
        c_j = c_row[j]
        if c_j != 0.0:
            for i in range(n):
                gain[i] += P[j, i] * c_j
    c_P_c = 0.0
    for i in range(n):
        c_P_c += c_row[i] * gain[i]
    s = c_P_c + r
    inv_s = 1.0 / s
    for i in range(n):
        gain[i] *= inv_s                     # K = a / s
        x[i] += gain[i] * innovation
    for i in range(n):
        k_i = gain[i]
        w_c = k_i * (s - c_P_c)              # (W c^T)_i = a_i - K_i c P c^T
        for j in range(i, n):                # W = P - K a^T, then W M^T + r K K^T
            value = P[i, j] - k_i * s * gain[j] + (r * k_i - w_c) * gain[j]
            P[i, j] = value
            P[j, i] = value
    return innovation, s


@numba.njit(inline="always", **_JIT)
def update(x, P, C, y, R_diag, gain, n_states):
    """Eq. 2 (and eq. 6), correction with the measurement vector y (diagonal R),
    one scalar measurement at a time.  Writes the gains (one row per
    measurement) into ``gain``; returns the normalised innovation squared (NIS)."""
    nis = 0.0
    for m in range(C.shape[0]):
        innovation, s = update_scalar(x, P, C[m], y[m], R_diag[m], gain[m], n_states)
        nis += innovation * innovation / s
    return nis


class LinearFilter(NamedTuple):
    """The arrays of a linear Kalman filter (eq. 1, 2) as the compiled loops take them,
    padded to ``STATE_SIZE`` states (``KalmanFilter.arrays``).  Units are the model's:
    states (x [m], v [m/s], i [A], x_d [m]) on the bearing axis, (x [m], v [m/s]) on the
    thrust collar; measurements y in sensor volts [V] or metres [m]."""

    x_hat: np.ndarray   # (STATE_SIZE,) estimate, corrected and predicted in place [state units]
    P: np.ndarray       # (STATE_SIZE, STATE_SIZE) error covariance, in place [state unit x state unit]
    A: np.ndarray       # (STATE_SIZE, STATE_SIZE) discrete state matrix [state unit per state unit]
    B: np.ndarray       # (STATE_SIZE,) column of the control input u [state unit per unit of u]
    C: np.ndarray       # (n_y, STATE_SIZE) measurement matrix [unit of y per state unit]
    Q: np.ndarray       # (STATE_SIZE, STATE_SIZE) process-noise covariance per sample [state units²]
    R_diag: np.ndarray  # (n_y,) measurement-noise variances [unit of y²]


class KalmanFilter:
    """Linear Kalman filter of eq. 2 with a diagonal measurement covariance.

    Parameters
    ----------
    A, B, C : array_like
        Discrete model (eq. 1); B is the column of the control input.
    Q : array_like
        Process-noise covariance.
    R_diag : array_like
        Measurement-noise variances (the diagonal of R).
    x0, P0 : array_like
        Initial estimate and its covariance.
    """

    def __init__(self, A, B, C, Q, R_diag, x0, P0):
        A, C, Q, P0 = (np.atleast_2d(np.asarray(M, dtype=float)) for M in (A, C, Q, P0))
        self.dim_x = A.shape[0]
        self.A, self.B, self.C = pad_square(A), pad_vector(B), pad_columns(C)
        self.Q, self.P = pad_square(Q), pad_square(P0)
        self.R_diag = np.ascontiguousarray(R_diag, dtype=float).ravel()
        self.state = pad_vector(x0)       # the estimate padded to STATE_SIZE, as the compiled steps read it
        self.gain = np.zeros((self.C.shape[0], STATE_SIZE))   # row j: gain of measurement j
        self._work_x, self._work_P = np.zeros(STATE_SIZE), np.zeros((STATE_SIZE, STATE_SIZE))

    @property
    def x(self) -> np.ndarray:
        """State estimate (a view of the model's states)."""
        return self.state[: self.dim_x]

    @property
    def covariance(self) -> np.ndarray:
        """Error covariance P of the estimate (a view)."""
        return self.P[: self.dim_x, : self.dim_x]

    def arrays(self) -> LinearFilter:
        """The filter's arrays for a compiled loop (the same arrays: the loop updates this filter)."""
        return LinearFilter(x_hat=self.state, P=self.P, A=self.A, B=self.B, C=self.C, Q=self.Q, R_diag=self.R_diag)

    def predict(self, u: float) -> None:
        """Prediction step of eq. 2 with control input u."""
        predict(self.state, self.P, self.A, self.B, float(u), self.Q, self._work_x, self._work_P)

    def update(self, y) -> None:
        """Correction step of eq. 2 with measurement vector y."""
        update(self.state, self.P, self.C, np.asarray(y, dtype=float), self.R_diag, self.gain, STATE_SIZE)


def pad_square(M) -> np.ndarray:
    """A square matrix embedded in the top-left corner of a STATE_SIZE square of zeros."""
    M = np.atleast_2d(np.asarray(M, dtype=float))
    if M.shape[0] > STATE_SIZE:
        raise ValueError(f"the linear filter kernels take at most {STATE_SIZE} states, got {M.shape[0]}")
    out = np.zeros((STATE_SIZE, STATE_SIZE))
    out[: M.shape[0], : M.shape[1]] = M
    return out


def pad_vector(v) -> np.ndarray:
    out = np.zeros(STATE_SIZE)
    v = np.ravel(np.asarray(v, dtype=float))
    out[: v.size] = v
    return out


def pad_columns(C) -> np.ndarray:
    C = np.atleast_2d(np.asarray(C, dtype=float))
    out = np.zeros((C.shape[0], STATE_SIZE))
    out[:, : C.shape[1]] = C
    return out


def correction(x_prior, P_prior, C, R_diag, y) -> dict:
    """The correction step of eq. 2 in batch form (numpy; for inspecting a filter, not
    for the loops): with S = C P⁻ Cᵀ + R and K = P⁻ Cᵀ S⁻¹, the innovation ν = y − C x⁻,
    x⁺ = x⁻ + K ν and the Joseph form P⁺ = (I − K C) P⁻ (I − K C)ᵀ + K R Kᵀ.

    For a diagonal R this equals the scalar-at-a-time ``update`` of the loops (up to
    rounding); ν and S are the batch ones (each measurement against the prior).
    Returns a dict with ``x``, ``P``, ``K`` (states x measurements), ``innovation``
    and ``S``."""
    x_prior, P_prior = np.asarray(x_prior, dtype=float), np.asarray(P_prior, dtype=float)
    C = np.atleast_2d(np.asarray(C, dtype=float))
    R = np.diag(np.ravel(np.asarray(R_diag, dtype=float)))
    S = C @ P_prior @ C.T + R
    K = np.linalg.solve(S.T, (P_prior @ C.T).T).T          # P Cᵀ S⁻¹ (S symmetric)
    innovation = np.ravel(np.asarray(y, dtype=float)) - C @ x_prior
    M = np.eye(len(x_prior)) - K @ C
    P = M @ P_prior @ M.T + K @ R @ K.T
    return {"x": x_prior + K @ innovation, "P": 0.5 * (P + P.T), "K": K, "innovation": innovation, "S": S}
