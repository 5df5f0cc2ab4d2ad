"""Extended Kalman filters of paper 000, §III (eq. 5-18).

Two filters observe one bearing axis from the same two measurements
(K_mx x or K_mx x_d, and K_mi i):

* ``ParameterEKF`` (§III-A): the linearised model of §II with the state
  augmented by the force-current and force-position factors,
  x = (x, v, i, k_i, k_x) (eq. 8), dynamics eq. 9.
* ``DisturbanceEKF`` (§III-B): the nonlinear model with the force law eq. 10,
  the sensor lag eq. 12 and the disturbance force as a state,
  x = (x, v, i, x_d, f_z) (eq. 13), dynamics eq. 14.

Both run the algorithm of eq. 6::

    prediction   x_{k|k-1} = f(x_{k-1|k-1}, u_{k-1})          RK4 over T, u held (§III-B)
                 P_{k|k-1} = Phi P_{k-1|k-1} Phi^T + Q          Phi = I + F T + F^2 T^2 / 2 (eq. 15)
    correction   K = P Gamma^T (Gamma P Gamma^T + R)^-1         Gamma = G = dg/dx (constant here)
                 x = x + K (y - g(x))
                 P = (I - K Gamma) P (I - K Gamma)^T + K R K^T  (Joseph form, symmetric PSD)

with F = df/dx evaluated at x_{k-1|k-1} (eq. 7).  R is diagonal (eq. 16), so
the correction processes the two measurements one scalar at a time, which
equals the matrix form above and needs no inverse.  Because g is linear
(Gamma = G), the correction is the linear filter's (``kalman.update``,
here with 5 states), and the prediction's covariance step is its
``kalman.propagate_covariance`` with Phi.  The paper specifies RK4
and eq. 15 for §III-B only; the lab uses the same discretisation for §III-A so
that the two filters differ only in their model.

The compiled kernels (``predict`` here, ``update``) work in place so that the
closed loop (``lab_modules.loops.radial_axis_ekf_loop``) can call them every 50 µs; the two
classes wrap them for step-by-step use.  ``physics`` is the float64 vector
(m, c_f, i0, delta0, cos(alpha), T_a, K_a, T_mx, T, K_mx, K_mi) of
``physics_vector``, the layout ``lab_modules.loops.radial_axis_ekf_loop`` passes for its
plant and its filter.
"""

from __future__ import annotations

import numba
import numpy as np

from lab_modules.estimators.kalman import propagate_covariance, update
from lab_modules.plants.radial_bearing import DEFAULT_SENSOR_LAG_S, RIG, BearingAxis

_JIT = {"nogil": True, "cache": True}

#: Both filters have five states (eq. 8 and eq. 13).
N_STATES = 5
#: Model selectors of the kernels.
LINEARISED, NONLINEAR = 0, 1

#: Eq. 16: measurement variances (position sensor, current sensor) [V^2].
PAPER_R_DIAG = np.array([7.1e-4, 1.4e-1])
#: Eq. 17: process-noise variances per sample of (x, v, i, x_d, f_z)
#: [m^2, m^2/s^2, A^2, m^2, N^2].
PAPER_Q_DIAG = np.array([0.0, 2.6e-10, 4.3e-1, 0.0, 1.0])


def physics_vector(rig: BearingAxis = RIG, sensor_lag_s: float = 0.0) -> np.ndarray:
    """(m, c_f, i0, delta0, cos(alpha), T_a, K_a, T_mx, T, K_mx, K_mi) of ``rig``."""
    return np.array([rig.equivalent_mass_kg, rig.force_factor_n_m2_per_a2, rig.i0_a, rig.delta0_m,
                     np.cos(rig.pole_angle_rad), rig.amplifier_lag_s, rig.amplifier_gain_a_per_v,
                     sensor_lag_s, rig.sample_time_s, rig.position_sensor_gain_v_per_m,
                     rig.current_sensor_gain_v_per_a])


def measurement_matrix(model: int, rig: BearingAxis = RIG) -> np.ndarray:
    """G = dg/dx = Gamma (eq. 9 and 14): rows K_mx x (or K_mx x_d) and K_mi i."""
    C = np.zeros((2, N_STATES))
    C[0, 0 if model == LINEARISED else 3] = rig.position_sensor_gain_v_per_m
    C[1, 2] = rig.current_sensor_gain_v_per_a
    return C


@numba.njit(**_JIT)
def local_factors(x, i, p):
    """(k_x [N/m], k_i [N/A]): the partial derivatives of eq. 10 at (x, i)."""
    c_f, i0, delta0, cos_a = p[1], p[2], p[3], p[4]
    gap_plus, gap_minus = delta0 - x * cos_a, delta0 + x * cos_a
    kx = 2.0 * c_f * cos_a * ((i0 + i) ** 2 / gap_plus**3 + (i0 - i) ** 2 / gap_minus**3)
    ki = 2.0 * c_f * ((i0 + i) / gap_plus**2 + (i0 - i) / gap_minus**2)
    return kx, ki


@numba.njit(**_JIT)
def derivative(model, s, u, p, ds):
    """f(x, u) in continuous time: eq. 9 (``LINEARISED``) or eq. 14 (``NONLINEAR``)."""
    m, Ta, Ka = p[0], p[5], p[6]
    ds[0] = s[1]
    ds[2] = (Ka * u - s[2]) / Ta
    if model == LINEARISED:                        # s = (x, v, i, k_i, k_x)
        ds[1] = (s[4] * s[0] + s[3] * s[2]) / m
        ds[3] = 0.0
    else:                                          # s = (x, v, i, x_d, f_z)
        c_f, i0, delta0, cos_a = p[1], p[2], p[3], p[4]
        f_m = c_f * ((i0 + s[2]) ** 2 / (delta0 - s[0] * cos_a) ** 2
                     - (i0 - s[2]) ** 2 / (delta0 + s[0] * cos_a) ** 2)
        ds[1] = (f_m + s[4]) / m
        ds[3] = (s[0] - s[3]) / p[7]
    ds[4] = 0.0


@numba.njit(**_JIT)
def jacobian(model, s, p, F):
    """F = df/dx of eq. 9 or eq. 14 at s (the input enters linearly)."""
    m, Ta = p[0], p[5]
    F[:, :] = 0.0
    F[0, 1] = 1.0
    F[2, 2] = -1.0 / Ta
    if model == LINEARISED:
        F[1, 0], F[1, 2] = s[4] / m, s[3] / m
        F[1, 3], F[1, 4] = s[2] / m, s[0] / m
    else:
        kx, ki = local_factors(s[0], s[2], p)
        F[1, 0], F[1, 2], F[1, 4] = kx / m, ki / m, 1.0 / m
        F[3, 0], F[3, 3] = 1.0 / p[7], -1.0 / p[7]


@numba.njit(**_JIT)
def transition_matrix(F, T, Phi):
    """Eq. 15: Phi = I + F T + F^2 T^2 / 2 (the series of e^{FT} cut after three terms)."""
    n = F.shape[0]
    for r in range(n):
        for c in range(n):
            acc = 0.0
            for k in range(n):
                acc += F[r, k] * F[k, c]
            Phi[r, c] = F[r, c] * T + 0.5 * T * T * acc + (1.0 if r == c else 0.0)


@numba.njit(**_JIT)
def factors_from_phi(Phi, p):
    """Eq. 18: k_x = 2m/T^2 (Phi_11 - 1), k_i = 2m/T^2 Phi_13 -> (k_x [N/m], k_i [N/A])."""
    scale = 2.0 * p[0] / (p[8] * p[8])
    return scale * (Phi[0, 0] - 1.0), scale * Phi[0, 2]


@numba.njit(**_JIT)
def rk4_step(model, s, u, p, work):
    """Classical fourth-order Runge-Kutta over one sample T, input held (§III-B)."""
    T = p[8]
    k1, k2, k3, k4, tmp = work[0], work[1], work[2], work[3], work[4]
    derivative(model, s, u, p, k1)
    for j in range(N_STATES):
        tmp[j] = s[j] + 0.5 * T * k1[j]
    derivative(model, tmp, u, p, k2)
    for j in range(N_STATES):
        tmp[j] = s[j] + 0.5 * T * k2[j]
    derivative(model, tmp, u, p, k3)
    for j in range(N_STATES):
        tmp[j] = s[j] + T * k3[j]
    derivative(model, tmp, u, p, k4)
    for j in range(N_STATES):
        s[j] += T / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])


@numba.njit(**_JIT)
def predict(model, x, P, u, Q, p, F, Phi, work):
    """Eq. 6, prediction, in place: Phi from F at x_{k-1|k-1} (eq. 7, 15), then
    x <- RK4(f, x, u) and P <- Phi P Phi^T + Q.  ``work``: (6, 5, 5) scratch."""
    jacobian(model, x, p, F)
    transition_matrix(F, p[8], Phi)
    rk4_step(model, x, u, p, work[0])
    propagate_covariance(P, Phi, Q, work[1], N_STATES)


def propagation(model: int, Q: np.ndarray, p: np.ndarray):
    """``predict`` as ``filter_history.FilterModel.propagation`` takes it: (x̂⁺, P⁺, u, q_scale, dt)
    -> (x̂⁻, P⁻, Φ_k, Q_k) with Φ_k from F at x̂⁺ (eq. 7, 15) and Q_k = q_scale Q (the sample time
    is the filter's own, p[8])."""
    def propagate(x, P, u, q_scale, dt):
        F, Phi, work = np.empty((N_STATES, N_STATES)), np.empty((N_STATES, N_STATES)), np.empty((6, N_STATES, N_STATES))
        Q_k = Q * q_scale
        predict(model, x, P, float(u[0]), Q_k, p, F, Phi, work)
        return x, P, Phi, Q_k
    return propagate


#: The prediction of eq. 6 in LaTeX (the filter debugger's equations).
PREDICTION_LATEX = (r"\mathrm{RK4}(f, \hat{x}^+_{k-1}, u_{k-1})",
                    r"\Phi_k P^+_{k-1}\Phi_k^T + Q,\ \Phi_k = I + F T + F^2 T^2/2,\ F = \partial f/\partial x|_{\hat{x}^+_{k-1}}")


class _ExtendedFilter:
    """Step-by-step wrapper of the kernels (filterpy style: ``x``, ``P``, ``Q``,
    ``R``, ``predict``, ``update``; ``Phi`` and ``nis`` of the last steps)."""

    model: int

    def __init__(self, x0, P0, Q=None, R_diag=None, rig: BearingAxis = RIG, sensor_lag_s: float = 0.0):
        self.x = np.array(x0, dtype=float)
        self.P = np.array(P0, dtype=float)
        self.Q = np.diag(PAPER_Q_DIAG) if Q is None else np.array(Q, dtype=float)
        self.R_diag = PAPER_R_DIAG.copy() if R_diag is None else np.array(R_diag, dtype=float)
        self.physics = physics_vector(rig, sensor_lag_s)
        self.C = measurement_matrix(self.model, rig)
        self.F, self.Phi = np.zeros((N_STATES, N_STATES)), np.eye(N_STATES)
        self.gain = np.zeros((2, N_STATES))
        self.nis = float("nan")
        self._work = np.zeros((6, N_STATES, N_STATES))

    @property
    def R(self) -> np.ndarray:
        return np.diag(self.R_diag)

    def predict(self, u: float) -> None:
        """Prediction of eq. 6 with the amplifier reference u = i_ref [V] held over T."""
        predict(self.model, self.x, self.P, float(u), self.Q, self.physics, self.F, self.Phi, self._work)

    def update(self, y) -> None:
        """Correction of eq. 6 with y = (position [V], current [V])."""
        self.nis = update(self.x, self.P, self.C, np.asarray(y, dtype=float), self.R_diag, self.gain, N_STATES)


class ParameterEKF(_ExtendedFilter):
    """§III-A: EKF on the linearised model augmented by k_i and k_x.

    State (eq. 8) x = (x [m], v [m/s], i [A], k_i [N/A], k_x [N/m]); dynamics
    eq. 9, m dv/dt = k_x x + k_i i, dk/dt = 0 + xi (the parameters change by
    process noise only, §II); measurements g = (K_mx x, K_mi i).  The paper
    gives no Q for this filter; the exercise chooses it.
    """

    model = LINEARISED


class DisturbanceEKF(_ExtendedFilter):
    """§III-B: EKF on the nonlinear model with sensor lag and disturbance force.

    State (eq. 13) x = (x [m], v [m/s], i [A], x_d [m], f_z [N]); dynamics
    eq. 14 (force law eq. 10, Newton eq. 11, amplifier eq. 4, sensor lag
    eq. 12 with T_mx = ``sensor_lag_s``), df_z/dt = 0 + xi; measurements
    g = (K_mx x_d, K_mi i).  Defaults: R of eq. 16, Q of eq. 17.
    """

    model = NONLINEAR

    def __init__(self, x0, P0, Q=None, R_diag=None, rig: BearingAxis = RIG, sensor_lag_s: float = DEFAULT_SENSOR_LAG_S):
        if not sensor_lag_s > 0.0:
            raise ValueError(f"the sensor lag T_mx must be positive (eq. 12), got {sensor_lag_s} s")
        super().__init__(x0, P0, Q, R_diag, rig, sensor_lag_s)

    def factors_from_phi(self) -> tuple[float, float]:
        """Eq. 18 on the last prediction's Phi: (k_x [N/m], k_i [N/A])."""
        return factors_from_phi(self.Phi, self.physics)
