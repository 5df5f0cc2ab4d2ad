"""The compiled closed loop of one bearing axis: plant, sensors, amplifier,
Kalman filter and a linear controller with optional state feedback on the
filter's estimate (LQG, paper §IV), stepped at T = 50 µs.

One call of ``run`` advances the loop by ``n_steps`` samples.  Per sample k:

1. sensors   y = (K_mx x_d + eta_x, K_mi i + eta_i)            (eq. 1, 14)
2. filter    correction with y                                   (eq. 2)
3. feedback  measured K_mx x_d + eta_x, or estimated K_mx x_hat  (paper §II, Fig. 3)
4. control   e = K_mx r - feedback;  i_ref = controller(e) - K_s x_hat (eq. 22; K_s = 0
             for a PID), clipped at the amplifier limit
5. filter    prediction with i_ref                               (eq. 2)
6. plant     one sample of eq. 3-4 (linear) or eq. 10-12 (nonlinear, RK4),
             plus process noise on v and i and the disturbance force f_z

The plant state is always (x, v, i, x_d); with no sensor lag x_d = x.  The
kernel releases the GIL, so sessions on different threads run in parallel.
Its arguments are named bundles (``Rotor``, ``LinearPlant``, the filter's
``kalman.LinearFilter``, the controller's ``pid.DiscreteController``,
``Feedback``, ``Inputs``, ``Noise``): a field is read by its name, never by
its place in a list.
"""

from __future__ import annotations

from typing import NamedTuple

import numba
import numpy as np

from lab_modules.controllers.pid import controller_step
from lab_modules.estimators.kalman import STATE_SIZE, predict, update

OK, DIVERGED, TOUCHDOWN = 0, 1, 2

#: Compiler options of the loop: no Python division checks (the divisions are
#: by physical constants) and fast arithmetic that still honours NaN and inf,
#: which the divergence check relies on.
JIT = {"nogil": True, "cache": True, "error_model": "numpy",
           "fastmath": {"nsz", "arcp", "contract", "afn", "reassoc"}}



class Rotor(NamedTuple):
    """The rotor on one bearing axis as the kernels step it (also ``radial_axis_ekf_loop``)."""

    state: np.ndarray     # (4,) true x [m], v [m/s], i [A], x_d [m] (sensed, lagged position), in place
    physics: np.ndarray   # (11,) m [kg], c_f [N m²/A²], i0 [A], delta0 [m], cos(alpha) [-], T_a [s],
    #                       K_a [A/V], T_mx [s], T [s], K_mx [V/m], K_mi [V/A] (eq. 10-12, the sensors)
    touchdown_m: float    # |x| [m] at which the rotor touches down


class LinearPlant(NamedTuple):
    """Which plant moves the rotor: eq. 10-12 by RK4, or the exact discrete linear eq. 3-4."""

    nonlinear: bool       # True: eq. 10-12 (RK4); False: the matrices below
    A: np.ndarray         # (4, 4) on (x [m], v [m/s], i [A], x_d [m]) [state units per state unit]
    B_u: np.ndarray       # (4,) column of i_ref [m/V, m/(s V), A/V, m/V]
    B_f: np.ndarray       # (4,) column of the force f_z [m/N, m/(s N), A/N, m/N]


class Feedback(NamedTuple):
    """What the controller acts on, what the loop adds to it, and the amplifier's limit."""

    use_estimate: bool     # feed back K_mx x_hat[0] instead of the measured position
    state_gain: np.ndarray  # (STATE_SIZE,) K_s on the corrected estimate (eq. 22) [V per state unit]
    u_limit_v: float       # amplifier input limit [V] (current limit / K_a)


class Inputs(NamedTuple):
    """Per-sample inputs of one call (n_steps samples)."""

    reference_m: np.ndarray    # (n_steps,) reference position r [m]
    disturbance_n: np.ndarray  # (n_steps,) disturbance force f_z [N]


class Noise(NamedTuple):
    """The noise of one call: standard normal draws and their scales."""

    draws: np.ndarray   # (n_steps, 4) standard normal draws (float32 or float64) [-]
    sigma: np.ndarray   # (4,) scales: process v [m/s], process i [A], sensor x [V], sensor i [V]


#: Columns of the trace array written by ``run`` after its time column [s].
TRACE_COLUMNS = ("x_true_m", "x_measured_m", "x_estimated_m", "x_sigma_m",
                 "current_a", "current_reference_v", "velocity_true_m_per_s",
                 "velocity_estimated_m_per_s")


@numba.njit(**JIT)
def _nonlinear_derivative(s, u, f_z, p, ds):
    """Right-hand side of eq. 10-12 for s = (x, v, i, x_d); p = physical constants."""
    m, c_f, i0, delta0, cos_a, Ta, Ka, Tmx = p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7]
    x, v, i = s[0], s[1], s[2]
    f_m = c_f * ((i0 + i) ** 2 / (delta0 - x * cos_a) ** 2
                 - (i0 - i) ** 2 / (delta0 + x * cos_a) ** 2)
    ds[0] = v
    ds[1] = (f_m + f_z) / m
    ds[2] = (Ka * u - i) / Ta
    ds[3] = (x - s[3]) / Tmx if Tmx > 0.0 else 0.0


@numba.njit(**JIT)
def rk4_step(s, u, f_z, p, T, k1, k2, k3, k4, tmp):
    """Classical fourth-order Runge-Kutta over one sample, input held (ZOH)."""
    _nonlinear_derivative(s, u, f_z, p, k1)
    for j in range(4):
        tmp[j] = s[j] + 0.5 * T * k1[j]
    _nonlinear_derivative(tmp, u, f_z, p, k2)
    for j in range(4):
        tmp[j] = s[j] + 0.5 * T * k2[j]
    _nonlinear_derivative(tmp, u, f_z, p, k3)
    for j in range(4):
        tmp[j] = s[j] + T * k3[j]
    _nonlinear_derivative(tmp, u, f_z, p, k4)
    for j in range(4):
        s[j] += T / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])


@numba.njit(**JIT)
def run(n_steps, first_step, rotor, linear_plant, kalman, controller, feedback, inputs, noise, trace):
    """Advance the closed loop by ``n_steps`` samples (see module docstring).

    Parameters (bundles of float64 arrays and numbers; arrays that hold state change in place)
    ----------
    first_step : index of the first sample (time = index * T).
    rotor : ``Rotor``, the true state and physical constants.
    linear_plant : ``LinearPlant``, the exact discrete linear plant when not ``nonlinear``.
    kalman : ``kalman.LinearFilter``, the filter's estimate, covariance and model (eq. 1, 2),
        padded to ``STATE_SIZE`` states (``KalmanFilter.arrays``).
    controller : ``pid.DiscreteController``, e [V] -> i_ref [V].
    feedback : ``Feedback``, measured or estimated position, state feedback, amplifier limit.
    inputs : ``Inputs``, per-sample reference [m] and force f_z [N].
    noise : ``Noise``, (n_steps, 4) standard normal draws and their scales.
    trace : (n_steps, 9) output: time [s], then the columns ``TRACE_COLUMNS``.

    Returns
    -------
    (status, steps_done): status OK, DIVERGED (non-finite) or TOUCHDOWN.
    """
    # every field read once, before the loop: an array read out of a bundle inside the loop
    # would cost a reference count per sample
    plant, physics, touchdown_m = rotor.state, rotor.physics, rotor.touchdown_m
    nonlinear, plant_A, plant_B_u, plant_B_f = linear_plant.nonlinear, linear_plant.A, linear_plant.B_u, linear_plant.B_f
    x_hat, P, A_f, B_f, C_f, Q_f, R_diag = kalman.x_hat, kalman.P, kalman.A, kalman.B, kalman.C, kalman.Q, kalman.R_diag
    ctrl, Ac, Bc, Cc, Dc = controller.state, controller.A, controller.B, controller.C, controller.D
    use_estimate, state_gain, u_limit = feedback.use_estimate, feedback.state_gain, feedback.u_limit_v
    reference_m, disturbance_n, draws, noise_sigma = inputs.reference_m, inputs.disturbance_n, noise.draws, noise.sigma
    T, Tmx, K_mx, K_mi = physics[8], physics[7], physics[9], physics[10]
    y = np.empty(2)
    gain = np.empty((2, STATE_SIZE))
    work_x, work_P = np.empty(STATE_SIZE), np.empty((STATE_SIZE, STATE_SIZE))
    new_plant, work_ctrl = np.empty(4), np.empty(max(ctrl.shape[0], 1))
    k1, k2, k3, k4, tmp = np.empty(4), np.empty(4), np.empty(4), np.empty(4), np.empty(4)
    for k in range(n_steps):
        # 1. sensors
        y[0] = K_mx * plant[3] + noise_sigma[2] * draws[k, 2]
        y[1] = K_mi * plant[2] + noise_sigma[3] * draws[k, 3]
        # 2. filter correction
        update(x_hat, P, C_f, y, R_diag, gain, STATE_SIZE)
        # 3.-4. feedback and controller
        fed_back = K_mx * x_hat[0] if use_estimate else y[0]
        e = K_mx * reference_m[k] - fed_back
        state_feedback = 0.0
        for j in range(STATE_SIZE):
            state_feedback += state_gain[j] * x_hat[j]
        u = controller_step(e, -state_feedback, u_limit, ctrl, Ac, Bc, Cc, Dc, work_ctrl)
        trace[k, 0] = (first_step + k) * T
        trace[k, 1] = plant[0]
        trace[k, 2] = y[0] / K_mx
        trace[k, 3] = x_hat[0]
        trace[k, 4] = np.sqrt(max(P[0, 0], 0.0))
        trace[k, 5] = plant[2]
        trace[k, 6] = u
        trace[k, 7] = plant[1]
        trace[k, 8] = x_hat[1]
        # 5. filter prediction
        predict(x_hat, P, A_f, B_f, u, Q_f, work_x, work_P)
        # 6. plant
        f_z = disturbance_n[k]
        if nonlinear:
            rk4_step(plant, u, f_z, physics, T, k1, k2, k3, k4, tmp)
        else:
            for r in range(4):
                acc = plant_B_u[r] * u + plant_B_f[r] * f_z
                for c in range(4):
                    acc += plant_A[r, c] * plant[c]
                new_plant[r] = acc
            for r in range(4):
                plant[r] = new_plant[r]
        if Tmx <= 0.0:
            plant[3] = plant[0]
        plant[1] += noise_sigma[0] * draws[k, 0]
        plant[2] += noise_sigma[1] * draws[k, 1]
        if not (np.isfinite(plant[0]) and np.isfinite(plant[1]) and np.isfinite(x_hat[0])
                and np.isfinite(P[0, 0])):
            return DIVERGED, k + 1
        if abs(plant[0]) >= touchdown_m:
            return TOUCHDOWN, k + 1
    return OK, n_steps
