"""The 4-state Kalman filter of paper 002 (§B, eq. 14-21) with a disturbance
force state, and its scheduled variants (§D, Fig. 8).

States z = (x [m], v [m/s], F_St [N], x_M [V]): rotor position and velocity, the
disturbance force as a random walk, and the "delayed" sensor state x_M of the
first-order-lag sensor (T_Sen, K_Sen, eq. 18).  The discrete model (eq. 15, 16,
19; the printed matrices are lost, reconstructed from those equations, the force
linearised as eq. 14 F_Magnet = k_i·i + k_s·x):

    x(k+1)   = x + T v + T²/(2m) (k_s x + k_i i + F_St - m g)
    v(k+1)   = v + T/m (k_s x + k_i i + F_St - m g)
    F_St(k+1) = F_St + w_F
    x_M(k+1) = e^{-T/T_Sen} x_M + K_Sen (1 - e^{-T/T_Sen}) x            (eq. 19)
    y(k)     = x_M(k) + n(k)                                              (eq. 21)

Inputs u = (i [A], 1): the coil control current and the weight m g.  Noise
(§B, after eq. 21): Q = var_process · b bᵀ + q_F on the force state, b the
current column of B; R = var_sensor.  The prediction and correction are eq. 9-13
(correction in Joseph form).

Variants (one kernel, ``mode``): fixed k_i, k_s (the centre values); k_i, k_s
scheduled on the operating point (i, x̂) by the FBFNN or by the exact no-intercept
LSM; and an extended Kalman filter whose prediction uses the force law eq. 1
itself (Jacobian: the tangent factors).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from lab_modules.plants.axial_bearing import magnet_force, tangent_factors

N_STATES = 4
# physics vector layout
MASS, SAMPLE, SENSOR_LAG, SENSOR_GAIN, GRAVITY, VAR_PROCESS, Q_FORCE, VAR_SENSOR, K_MAGNET, GAP, BIAS = range(11)
N_PHYSICS = 11


def physics_vector(mass_kg, sample_time_s, sensor_lag_s, sensor_gain_v_per_m, gravity, var_process_a2,
                   q_force_n2, var_sensor_v2, k_magnet, gap_m, bias_current_a) -> np.ndarray:
    return np.array([mass_kg, sample_time_s, sensor_lag_s, sensor_gain_v_per_m, gravity, var_process_a2,
                     q_force_n2, var_sensor_v2, k_magnet, gap_m, bias_current_a], dtype=np.float64)


@njit(cache=True, nogil=True)
def model_matrices(k_i, k_s, physics, A, B):
    """Fill A (4×4) and B (4×2, columns: current, weight) of the discrete model."""
    m, T = physics[MASS], physics[SAMPLE]
    a = np.exp(-T / physics[SENSOR_LAG])
    A[:, :] = 0.0
    A[0, 0] = 1.0 + k_s * T * T / (2 * m)
    A[0, 1] = T
    A[0, 2] = T * T / (2 * m)
    A[1, 0] = k_s * T / m
    A[1, 1] = 1.0
    A[1, 2] = T / m
    A[2, 2] = 1.0
    A[3, 0] = physics[SENSOR_GAIN] * (1.0 - a)
    A[3, 3] = a
    B[:, :] = 0.0
    B[0, 0] = k_i * T * T / (2 * m)
    B[1, 0] = k_i * T / m
    B[0, 1] = -physics[GRAVITY] * T * T / 2
    B[1, 1] = -physics[GRAVITY] * T


@njit(cache=True, nogil=True)
def process_noise(physics, B, Q):
    """Q = var_process · b bᵀ + q_F e₃e₃ᵀ (§B)."""
    for r in range(N_STATES):
        for c in range(N_STATES):
            Q[r, c] = physics[VAR_PROCESS] * B[r, 0] * B[c, 0]
    Q[2, 2] += physics[Q_FORCE]


@njit(cache=True, nogil=True)
def correct(z, P, y, var_sensor):
    """Eq. 11-13 with H = (0, 0, 0, 1), P in Joseph form (exact for this H):

        P⁺ = (I - K H) P (I - K H)ᵀ + K R Kᵀ,   K = P Hᵀ / (H P Hᵀ + R)

    written out for this H, in place and without temporaries (the kernels call it four times a
    sample): row r of W = (I - K H) P is P_r - K_r P_3 (for r = 3: (1 - K_3) P_3), and
    P⁺_rc = W_rc - K_c W_r3 (for c = 3: (1 - K_3) W_r3) + R K_r K_c."""
    s = P[3, 3] + var_sensor
    gains = (P[0, 3] / s, P[1, 3] / s, P[2, 3] / s, P[3, 3] / s)
    innovation = y - z[3]
    for r in range(N_STATES):
        z[r] += gains[r] * innovation
    last = 1.0 - gains[3]
    for r in (0, 1, 2, 3):                          # row 3 last: the others read its old values
        if r < 3:
            w = (P[r, 0] - gains[r] * P[3, 0], P[r, 1] - gains[r] * P[3, 1],
                 P[r, 2] - gains[r] * P[3, 2], P[r, 3] - gains[r] * P[3, 3])
        else:
            w = (last * P[3, 0], last * P[3, 1], last * P[3, 2], last * P[3, 3])
        for c in range(3):
            P[r, c] = w[c] - gains[c] * w[3] + var_sensor * gains[r] * gains[c]
        P[r, 3] = last * w[3] + var_sensor * gains[r] * gains[3]


@njit(cache=True, nogil=True)
def row_times(A, P, r):
    """Row r of A P (4×4), summed left to right."""
    return (A[r, 0] * P[0, 0] + A[r, 1] * P[1, 0] + A[r, 2] * P[2, 0] + A[r, 3] * P[3, 0],
            A[r, 0] * P[0, 1] + A[r, 1] * P[1, 1] + A[r, 2] * P[2, 1] + A[r, 3] * P[3, 1],
            A[r, 0] * P[0, 2] + A[r, 1] * P[1, 2] + A[r, 2] * P[2, 2] + A[r, 3] * P[3, 2],
            A[r, 0] * P[0, 3] + A[r, 1] * P[1, 3] + A[r, 2] * P[2, 3] + A[r, 3] * P[3, 3])


@njit(cache=True, nogil=True)
def propagate_covariance(P, A, Q):
    """P ← A P Aᵀ + Q (eq. 10), in place; A P held in locals (no temporaries: the kernels call
    this four times a sample, and a 4×4 through BLAS costs more than its 128 products)."""
    AP = (row_times(A, P, 0), row_times(A, P, 1), row_times(A, P, 2), row_times(A, P, 3))
    for r in range(N_STATES):
        w = AP[r]
        for c in range(N_STATES):
            P[r, c] = w[0] * A[c, 0] + w[1] * A[c, 1] + w[2] * A[c, 2] + w[3] * A[c, 3] + Q[r, c]


@njit(cache=True, nogil=True)
def predict_linear(z, P, A, B, Q, current_a):
    """Eq. 9-10."""
    x, v, f, xm = z[0], z[1], z[2], z[3]
    for r in range(N_STATES):
        z[r] = A[r, 0] * x + A[r, 1] * v + A[r, 2] * f + A[r, 3] * xm + B[r, 0] * current_a + B[r, 1]
    propagate_covariance(P, A, Q)


@njit(cache=True, nogil=True)
def predict_exact_force(z, P, physics, current_a, A, B, Q):
    """EKF prediction: the same discretisation with the force of eq. 1 at the
    estimate (F_Magnet(i, x̂) in place of k_i i + k_s x̂), P through the Jacobian
    (the linear model at the tangent factors)."""
    m, T = physics[MASS], physics[SAMPLE]
    k_i, k_s = tangent_factors(current_a, z[0], physics[K_MAGNET], physics[GAP], physics[BIAS])
    model_matrices(k_i, k_s, physics, A, B)
    process_noise(physics, B, Q)
    force = magnet_force(current_a, z[0], physics[K_MAGNET], physics[GAP], physics[BIAS])
    accel = (force + z[2]) / m - physics[GRAVITY]
    a = A[3, 3]
    x, v, f, xm = z[0], z[1], z[2], z[3]
    z[0] = x + T * v + 0.5 * T * T * accel
    z[1] = v + T * accel
    z[2] = f
    z[3] = a * xm + physics[SENSOR_GAIN] * (1.0 - a) * x
    propagate_covariance(P, A, Q)


class AxialKalmanFilter:
    """The linear filter at fixed k_i [N/A], k_s [N/m], step by step (for tests and notebooks)."""

    def __init__(self, k_i: float, k_s: float, physics: np.ndarray, z0=None, P0=None):
        self.physics = np.asarray(physics, float)
        self.A, self.B, self.Q = np.zeros((4, 4)), np.zeros((4, 2)), np.zeros((4, 4))
        model_matrices(k_i, k_s, self.physics, self.A, self.B)
        process_noise(self.physics, self.B, self.Q)
        self.z = np.zeros(4) if z0 is None else np.array(z0, float)
        self.P = np.eye(4) * 1e-12 if P0 is None else np.array(P0, float)

    def predict(self, current_a: float) -> None:
        predict_linear(self.z, self.P, self.A, self.B, self.Q, current_a)

    def update(self, y_v: float) -> None:
        correct(self.z, self.P, y_v, self.physics[VAR_SENSOR])


#: The filters' states and measurement (label, SI unit), for the inspector and the debugger.
STATES = (("position x", "m"), ("velocity v", "m/s"), ("disturbance force F_St", "N"), ("sensor state x_M", "V"))
MEASUREMENTS = (("position sensor", "V"),)
H = np.array([[0.0, 0.0, 0.0, 1.0]])
#: The prediction (eq. 9-10) in LaTeX, its matrices scheduled on (i, x̂⁺).
PREDICTION_LATEX = (r"A_k\hat{z}^+_{k-1} + B_k (i_{k-1}, 1)^T",
                    r"A_k P^+_{k-1} A_k^T + Q_k,\ A_k, B_k, Q_k \text{ at } k_i, k_s(i_{k-1}, \hat{x}^+_{k-1})")


def propagation(physics: np.ndarray, factors=None):
    """The prediction as ``filter_history.FilterModel.propagation`` takes it: (ẑ⁺, P⁺, u = (i [A],),
    q_scale, dt) -> (ẑ⁻, P⁻, A_k, Q_k).  ``factors(i, x̂⁺) -> (k_i [N/A], k_s [N/m])`` schedules
    the linear model (eq. 9-10, ``predict_linear``); None: the EKF with the force law
    (``predict_exact_force``).  q_scale multiplies var_process and q_F, hence Q_k."""
    def propagate(z, P, u, q_scale, dt):
        scaled = physics.copy()
        scaled[VAR_PROCESS] *= q_scale
        scaled[Q_FORCE] *= q_scale
        A, B, Q = np.zeros((N_STATES, N_STATES)), np.zeros((N_STATES, 2)), np.zeros((N_STATES, N_STATES))
        current = float(u[0])
        if factors is None:
            predict_exact_force(z, P, scaled, current, A, B, Q)
        else:
            k_i, k_s = factors(current, z[0])
            model_matrices(float(k_i), float(k_s), scaled, A, B)
            process_noise(scaled, B, Q)
            predict_linear(z, P, A, B, Q, current)
        return z, P, A, Q
    return propagate
