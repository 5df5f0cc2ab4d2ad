"""Extended Kalman filters for the maglev ball (paper 004, §2.5, App. F-G).

Continuous-discrete EKF (the paper's final filter, §2.5, App. G)
-----------------------------------------------------------------
The model is continuous (eq. 2.33), the position is sampled every dt
(eq. 2.34, y_k = x1 + v_k, var v_k = R).  At a sample, the update::

    K_k   = P^- H^T (H P^- H^T + R)^-1                       (2.40)
    x^+   = x^- + K_k (y_k - h(x^-))                          (2.41)
    P^+   = (I - K_k H) P^-                                   (2.42)

(computed in Joseph form (I - K H) P (I - K H)^T + K R K^T, equal to eq. 2.42
for the optimal gain and symmetric PSD by construction); between samples the
estimate and covariance are integrated with the input held::

    x'    = f(x) + g u                                        (2.43)
    F     = df/dx at x(t)                                     (2.44)
    P'    = F P + P F^T + Psi Q Psi^T                         (2.45)

with Psi = I, so Q holds the spectral densities of the process noise on
(x1, x2, x3) [m^2/s, m^2/s^3, A^2/s].  Integration: fixed-step RK4 of
(x, P) jointly, as the paper's Simulink solver does (§3.2.1).

Continuous-time EKF (the paper's first filter, App. G "Extended Kalman Filter")
----------------------------------------------------------------------------
The Kalman-Bucy form treats the sampled position as a continuous signal::

    x' = f(x) + g u + P H^T R_c^-1 (y - h(x))
    P' = F P + P F^T + Q - P H^T R_c^-1 H P

The paper's code uses the sample variance r = (1 mm)^2 as R_c.  A continuous
measurement's noise density is r dt for samples of variance r taken every dt,
so the paper's filter weights each measurement 1/dt = 1000 times too little:
its gain is about 30 times smaller than the continuous-discrete one and its
covariance no longer describes its error.  With ``density_from_samples=True``
the class uses R_c = r dt and behaves like the continuous-discrete filter for
small dt.  This is the lab's reading of why the paper dropped the filter
(§3.5.1 names "the discrete sampling of the output" as the foremost suspect).
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from lab_modules.estimators.filter_history import FilterModel
from lab_modules.estimators.kalman import update_scalar
from lab_modules.plants.maglev_ball import TABLE_3_1, MaglevPlant, derivative, jacobian

_JIT = {"nogil": True, "cache": True}


@numba.njit(**_JIT)
def _rates(x, P, u, y, p, Q, inverse_r_c, dx, dP):
    """Eq. 2.43 and 2.45 at (x, P).  With inverse_r_c = 1/R_c > 0 they gain the Kalman-Bucy
    terms of a continuous measurement y (the continuous-time filter); with 0 they are the
    continuous-discrete filter's propagation between samples."""
    f = derivative(x, u, p)
    F = jacobian(x, p)
    FP = F @ P
    correction = inverse_r_c * (y - x[0])
    for i in range(3):
        dx[i] = f[i] + P[i, 0] * correction
        for j in range(3):
            dP[i, j] = FP[i, j] + FP[j, i] + Q[i, j] - P[i, 0] * P[0, j] * inverse_r_c


@numba.njit(**_JIT)
def _rk4_step(x, P, u, y, p, Q, inverse_r_c, h):
    """One classical RK4 step of ``_rates`` over h for (x, P) jointly, in place; P kept symmetric."""
    k_x = np.empty((4, 3))
    k_P = np.empty((4, 3, 3))
    xs = np.empty(3)
    Ps = np.empty((3, 3))
    weights = (0.0, 0.5, 0.5, 1.0)
    for stage in range(4):
        w = weights[stage] * h
        for i in range(3):
            xs[i] = x[i] + (w * k_x[stage - 1, i] if stage > 0 else 0.0)
            for j in range(3):
                Ps[i, j] = P[i, j] + (w * k_P[stage - 1, i, j] if stage > 0 else 0.0)
        _rates(xs, Ps, u, y, p, Q, inverse_r_c, k_x[stage], k_P[stage])
    for i in range(3):
        x[i] += h / 6.0 * (k_x[0, i] + 2.0 * k_x[1, i] + 2.0 * k_x[2, i] + k_x[3, i])
        for j in range(3):
            P[i, j] += h / 6.0 * (k_P[0, i, j] + 2.0 * k_P[1, i, j] + 2.0 * k_P[2, i, j] + k_P[3, i, j])
    for i in range(3):
        for j in range(i + 1, 3):
            s = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = s
            P[j, i] = s


@numba.njit(**_JIT)
def propagate(x, P, u, p, Q, dt, n_substeps):
    """Integrate eq. 2.43-2.45 over dt with u held: RK4 in ``n_substeps`` steps (in place)."""
    for _ in range(n_substeps):
        _rk4_step(x, P, u, 0.0, p, Q, 0.0, dt / n_substeps)


#: Eq. 2.43-2.45 in LaTeX (the filter debugger's equations); states (x1 [m], x2 [m/s], x3 [A]).
PREDICTION_LATEX = (r"\hat{x}^+_{k-1} + \int (f(x) + g\,u_{k-1})\,dt",
                    r"P^+_{k-1} + \int (F P + P F^T + Q)\,dt,\ F = \partial f/\partial x|_{x(t)}")
STATES = (("air gap x₁", "m"), ("ball velocity x₂", "m/s"), ("coil current x₃", "A"))
MEASUREMENTS = (("position sensor", "m"),)


def history_model(title: str, sample_time_s: float, constants: np.ndarray, Q, r_m2: float, n_substeps: int,
                  fixed_interval: bool) -> FilterModel:
    """The filter as ``filter_history`` replays it: H = [1 0 0], R = r, and ``propagate`` as its
    propagation (x̂⁺, P⁺, u = (voltage [V],), q_scale, dt) -> (x̂⁻, P⁻, None, None) - eq. 2.45
    integrates P, there is no one Φ_k.  ``fixed_interval``: over ``sample_time_s`` as the loop does
    (else over the interval between the samples' times, as ``run_observer`` on a recording)."""
    Q = np.asarray(Q, dtype=float)

    def history_step(x, P, u, q_scale, dt):
        propagate(x, P, float(u[0]), constants, Q * q_scale, sample_time_s if fixed_interval else dt, n_substeps)
        return x, P, None, None
    return FilterModel.propagated(title, sample_time_s, 1, [_POSITION_ROW], Q, [r_m2], STATES, MEASUREMENTS,
                                  history_step, PREDICTION_LATEX)


#: H = dh/dx for h(x) = x1 (the position sensor).
_POSITION_ROW = np.array([1.0, 0.0, 0.0])


@numba.njit(**_JIT)
def update(x, P, y, r, gain):
    """Eq. 2.40-2.42 for h(x) = x1 (H = [1 0 0]), Joseph form, in place: the linear
    filter's scalar correction (``estimators.update_scalar``) with 3 states.

    Writes the Kalman gain into ``gain``; returns (innovation, its variance S)."""
    return update_scalar(x, P, _POSITION_ROW, y, r, gain, 3)


@numba.njit(**_JIT)
def bucy_step(x, P, u, y, p, Q, r_c, dt):
    """One RK4 step of the continuous-time EKF over dt (u and y held), in place."""
    _rk4_step(x, P, u, y, p, Q, 1.0 / r_c, dt)


class ContinuousDiscreteEKF:
    """Continuous-discrete EKF of paper 004 §2.5 (eq. 2.40-2.45), filterpy style.

    Parameters
    ----------
    Q : array_like (3, 3)
        Process-noise spectral densities (eq. 2.45 with Psi = I) [m^2/s, m^2/s^3, A^2/s].
    R : float
        Variance of one position sample (eq. 2.34) [m^2].
    x0, P0 : array_like
        Initial estimate (eq. 2.37) and covariance (eq. 2.38).
    plant : MaglevPlant
        The filter's model (Table 3.1 by default).
    n_substeps : int
        RK4 steps per propagation interval.

    After ``update`` the attributes ``y`` (innovation), ``S`` (its variance)
    and ``nis`` (y^2 / S) describe the last measurement, as in filterpy.
    """

    def __init__(self, Q, R, x0, P0, plant: MaglevPlant = TABLE_3_1, n_substeps: int = 1):
        self.Q = np.array(Q, dtype=float)
        self.R = float(R)
        self.x = np.array(x0, dtype=float)
        self.P = np.array(P0, dtype=float)
        self.constants = plant.constants()
        self.n_substeps = int(n_substeps)
        self.K = np.zeros(3)
        self.y = 0.0
        self.S = float(self.P[0, 0] + self.R)

    @property
    def nis(self) -> float:
        """Normalised innovation squared of the last update, y^2 / S (chi^2 with 1 dof)."""
        return self.y * self.y / self.S

    def predict(self, u: float, dt: float) -> None:
        """Eq. 2.43-2.45 from the last sample to the next, coil voltage u [V] held."""
        propagate(self.x, self.P, float(u), self.constants, self.Q, float(dt), self.n_substeps)

    def update(self, z: float) -> None:
        """Eq. 2.40-2.42 with the measured position z [m]."""
        self.y, self.S = update(self.x, self.P, float(z), self.R, self.K)


class ContinuousTimeEKF:
    """The paper's first, continuous-time EKF (App. G), kept to show why it was dropped.

    Parameters as ``ContinuousDiscreteEKF``.  ``density_from_samples`` chooses
    the measurement-noise density: False = the paper's R_c = R (a sample
    variance used as a density), True = R_c = R dt (consistent with samples of
    variance R taken every dt).
    """

    def __init__(self, Q, R, x0, P0, plant: MaglevPlant = TABLE_3_1, density_from_samples: bool = False):
        self.Q = np.array(Q, dtype=float)
        self.R = float(R)
        self.x = np.array(x0, dtype=float)
        self.P = np.array(P0, dtype=float)
        self.constants = plant.constants()
        self.density_from_samples = density_from_samples

    def measurement_density(self, dt: float) -> float:
        """R_c [m^2 s] (or the paper's R [m^2] used as one)."""
        return self.R * dt if self.density_from_samples else self.R

    def propagate(self, u: float, z: float, dt: float) -> None:
        """Integrate the Kalman-Bucy equations over dt with u and z held."""
        bucy_step(self.x, self.P, float(u), float(z), self.constants, self.Q,
                  self.measurement_density(dt), float(dt))


#: Columns written by ``run_observer`` (one row per sample, after the update).
OBSERVER_COLUMNS = ("x_estimated_m", "velocity_estimated_m_per_s", "current_estimated_a",
                    "x_sigma_m", "velocity_sigma_m_per_s", "current_sigma_a",
                    "innovation_m", "innovation_sigma_m", "nis")


class RecordedSamples(NamedTuple):
    """A recording as ``run_observer`` reads it."""

    time_s: np.ndarray       # (n,) sample times t_k [s]
    measured_m: np.ndarray   # (n,) measured gap y_k [m]
    voltage_v: np.ndarray    # (n,) coil voltage u_k [V], held until t_{k+1}


class ObserverFilter(NamedTuple):
    """The continuous-discrete EKF's arrays as ``run_observer`` takes them; states (x1 [m], x2 [m/s], x3 [A])."""

    x_hat: np.ndarray      # (3,) estimate, in place [m, m/s, A]
    P: np.ndarray          # (3, 3) error covariance, in place [state unit x state unit]
    Q: np.ndarray          # (3, 3) process noise spectral densities [m²/s, m²/s³, A²/s on the diagonal]
    R_m2: float            # measurement variance r [m²]
    constants: np.ndarray  # (5,) the model's m [kg], L_c [H], R_c [Ω], C [N m²/A²], g [m/s²]
    substeps: int          # RK4 steps per sample interval of the propagation


@numba.njit(**_JIT)
def run_observer(samples, ekf, out, priors):
    """The continuous-discrete EKF (an ``ObserverFilter``) as a pure observer of a recording
    (``RecordedSamples``; §3.5, Fig. 3.23).

    At each sample k: keep the prior (x⁻ in ``priors[k, :3]``, P⁻ row by row in
    ``priors[k, 3:]``; the filter inspector redoes the correction from it),
    update with y_k (eq. 2.40-2.42), write a row of ``OBSERVER_COLUMNS``,
    propagate to t_{k+1} with the recorded voltage u_k held (eq. 2.43-2.45).
    Returns the number of rows written (fewer than the samples if the estimate
    stops being finite)."""
    time_s, measured_m, voltage_v = samples.time_s, samples.measured_m, samples.voltage_v
    x, P, Q, r, p = ekf.x_hat, ekf.P, ekf.Q, ekf.R_m2, ekf.constants
    gain = np.empty(3)
    n = time_s.shape[0]
    for k in range(n):
        prior = priors[k]
        for i in range(3):
            prior[i] = x[i]
            for j in range(3):
                prior[3 + 3 * i + j] = P[i, j]
        innovation, s = update(x, P, measured_m[k], r, gain)
        row = out[k]
        row[0], row[1], row[2] = x[0], x[1], x[2]
        row[3], row[4], row[5] = np.sqrt(max(P[0, 0], 0.0)), np.sqrt(max(P[1, 1], 0.0)), \
            np.sqrt(max(P[2, 2], 0.0))
        row[6], row[7], row[8] = innovation, np.sqrt(s), innovation * innovation / s
        if not (np.isfinite(x[0]) and np.isfinite(x[1]) and np.isfinite(x[2]) and np.isfinite(P[0, 0])
                and x[0] > 0.0):
            return k
        if k + 1 < n:
            propagate(x, P, voltage_v[k], p, Q, time_s[k + 1] - time_s[k], ekf.substeps)
    return n
