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
def product(left, right, out):
    """out = left @ right for the filter's small matrices: plain loops (a BLAS call and its
    temporaries cost more than the 64 products of a 4×4; the kernels call this several times a sample)."""
    for r in range(left.shape[0]):
        for c in range(right.shape[1]):
            acc = 0.0
            for j in range(left.shape[1]):
                acc += left[r, j] * right[j, c]
            out[r, c] = acc


@njit(cache=True, nogil=True)
def sandwich(left, P, out, work):
    """out = left P leftᵀ (``work``: a scratch matrix of P's size)."""
    product(left, P, work)
    for r in range(out.shape[0]):
        for c in range(out.shape[1]):
            acc = 0.0
            for j in range(work.shape[1]):
                acc += work[r, j] * left[c, j]
            out[r, c] = acc


@njit(cache=True, nogil=True)
def correct(z, P, y, var_sensor):
    """Eq. 11-13 with H = (0, 0, 0, 1), P in Joseph form (exact for this H)."""
    s = P[3, 3] + var_sensor
    K = P[:, 3] / s
    innovation = y - z[3]
    for r in range(N_STATES):
        z[r] += K[r] * innovation
    # Joseph: (I - K H) P (I - K H)ᵀ + K R Kᵀ
    IKH = np.eye(N_STATES)
    for r in range(N_STATES):
        IKH[r, 3] -= K[r]
    work = np.empty((N_STATES, N_STATES))
    sandwich(IKH, P, P, work)
    for r in range(N_STATES):
        for c in range(N_STATES):
            P[r, c] += var_sensor * K[r] * K[c]


@njit(cache=True, nogil=True)
def propagate_covariance(P, A, Q):
    """P ← A P Aᵀ + Q (eq. 10), in place."""
    work, out = np.empty((N_STATES, N_STATES)), np.empty((N_STATES, N_STATES))
    sandwich(A, P, out, work)
    for r in range(N_STATES):
        for c in range(N_STATES):
            P[r, c] = out[r, c] + Q[r, c]


@njit(cache=True, nogil=True)
def predict_linear(z, P, A, B, Q, current_a):
    """Eq. 9-10."""
    previous = z.copy()
    for r in range(N_STATES):
        acc = 0.0
        for c in range(N_STATES):
            acc += A[r, c] * previous[c]
        z[r] = acc + B[r, 0] * current_a + B[r, 1]
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
