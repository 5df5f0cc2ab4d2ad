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
"""

from __future__ import annotations

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
def _rk4_step(s, u, f_z, p, T, k1, k2, k3, k4, tmp):
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
def run(n_steps, first_step, plant, plant_A, plant_B_u, plant_B_f, nonlinear, physics,
        x_hat, P, A_f, B_f, C_f, Q_f, R_diag,
        ctrl, Ac, Bc, Cc, Dc, state_gain, u_limit, use_estimate,
        reference_m, disturbance_n, noise, noise_sigma, touchdown_m, trace):
    """Advance the closed loop by ``n_steps`` samples (see module docstring).

    Parameters (float64 arrays unless said, modified in place where they hold state)
    ----------
    first_step : index of the first sample (time = index * T).
    plant : (4,) true state (x [m], v [m/s], i [A], x_d [m]).
    plant_A, plant_B_u, plant_B_f : exact discrete linear plant (4x4, 4, 4);
        used when ``nonlinear`` is False.
    physics : (11,) m, c_f, i0, delta0, cos(alpha), T_a, K_a, T_mx, T, K_mx, K_mi
        (eq. 10-12 and the sensor gains).
    x_hat, P, A_f, B_f, C_f, Q_f, R_diag : the filter's estimate, covariance
        and model (eq. 1, 2), padded to ``STATE_SIZE`` states (``KalmanFilter``).
    ctrl, Ac, Bc, Cc, Dc : controller state and discrete matrices (e [V] -> i_ref [V]).
    state_gain : (STATE_SIZE,) K_s on the corrected estimate x_hat [V per state unit].
    u_limit : amplifier input limit [V] (current limit / K_a).
    use_estimate : feed back K_mx x_hat[0] instead of the measured position.
    reference_m, disturbance_n : per-sample reference position [m] and force f_z [N].
    noise : (n_steps, 4) standard normal draws (float32 or float64); noise_sigma : (4,) their scales,
        (process v [m/s], process i [A], sensor x [V], sensor i [V]).
    touchdown_m : |x| at which the rotor touches down.
    trace : (n_steps, 9) output: time [s], then the columns ``TRACE_COLUMNS``.

    Returns
    -------
    (status, steps_done): status OK, DIVERGED (non-finite) or TOUCHDOWN.
    """
    T, Tmx, K_mx, K_mi = physics[8], physics[7], physics[9], physics[10]
    y = np.empty(2)
    gain = np.empty((2, STATE_SIZE))
    work_x, work_P = np.empty(STATE_SIZE), np.empty((STATE_SIZE, STATE_SIZE))
    new_plant, work_ctrl = np.empty(4), np.empty(max(ctrl.shape[0], 1))
    k1, k2, k3, k4, tmp = np.empty(4), np.empty(4), np.empty(4), np.empty(4), np.empty(4)
    for k in range(n_steps):
        # 1. sensors
        y[0] = K_mx * plant[3] + noise_sigma[2] * noise[k, 2]
        y[1] = K_mi * plant[2] + noise_sigma[3] * noise[k, 3]
        # 2. filter correction
        update(x_hat, P, C_f, y, R_diag, gain, STATE_SIZE)
        # 3.-4. feedback and controller
        feedback = K_mx * x_hat[0] if use_estimate else y[0]
        e = K_mx * reference_m[k] - feedback
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
            _rk4_step(plant, u, f_z, physics, T, k1, k2, k3, k4, tmp)
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
        plant[1] += noise_sigma[0] * noise[k, 0]
        plant[2] += noise_sigma[1] * noise[k, 1]
        if not (np.isfinite(plant[0]) and np.isfinite(plant[1]) and np.isfinite(x_hat[0])
                and np.isfinite(P[0, 0])):
            return DIVERGED, k + 1
        if abs(plant[0]) >= touchdown_m:
            return TOUCHDOWN, k + 1
    return OK, n_steps
