"""LQR with integral action for the bearing axis (paper 000, §IV, eq. 19-22).

``StateFeedback`` is the LQG regulator u = -K x_hat plus the superimposed
integral controller on the position error; its integral part is a discrete
``control.StateSpace`` on e [V] (stepped by ``controllers.pid.controller_step``)
and the state gain acts on the Kalman filter's estimate.  ``lqr`` computes it
by python-control's ``dlqr``; ``PAPER_LQG`` holds the paper's printed gains.
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numpy as np

from lab_modules.plants.radial_bearing import RIG, BearingAxis


@dataclass(frozen=True)
class StateFeedback:
    """State feedback with superimposed integral action (paper 000, §IV, Fig. 6)::

        u_k = i_ref,k = -K (x, v, i)_k + K_I xi_k,    xi_{k+1} = xi_k + T (r_k - x_k)

    Units (the lab's reading of eq. 22, which prints the numbers without
    units): the state (x [m], v [m/s], i [A]) is in SI units as in eq. 3-4 and
    u = i_ref is the amplifier's input in volts (eq. 4, K_a = 5 A/V), so
    K = (K_x [V/m], K_v [V s/m], K_i [V/A]) and K_I [V/(m s)] acts on the
    time integral of the position error in metres.  The paper's "s^-1" for K_I
    omits the V/m that it also omits for K_x.  Why this reading:

    * the state feedback then has the static stiffness
      K_a k_i K_x / (1 + K_a K_i) - k_x = 3.9 N/µm, the order of the paper's
      dynamic stiffness of 6.7 N/µm (an output in amperes would give
      0.4 N/µm, a state in sensor volts 2e4 times more: unstable);
    * the closed loop's poles are well damped (-202 ± 216j, -335, -2700 rad/s)
      and the integral's corner K_I / K_x = 103 rad/s lies below them;
    * the four numbers are exactly the discrete LQR (eq. 19-21) of the
      integral-augmented model for diagonal weights (see ``PAPER_LQR_WEIGHTS``),
      i.e. they are LQ-optimal as the paper says.

    Attributes
    ----------
    state_gain : tuple
        K = (K_x [V/m], K_v [V s/m], K_i [V/A]) on the estimate (x, v, i).
    integral_gain_v_per_m_s : float
        K_I [V/(m s)] on the integral of the position error.
    """

    state_gain: tuple[float, float, float]
    integral_gain_v_per_m_s: float

    def integrator(self, sample_time_s: float = RIG.sample_time_s,
                   position_gain_v_per_m: float = RIG.position_sensor_gain_v_per_m) -> control.StateSpace:
        """The integral controller as a discrete system e [V] -> u [V].

        The loop's control error is in sensor volts, e = K_mx (r - x); the state
        xi [m s] sums it forward-Euler, as in the augmented model of ``lqr``."""
        return control.ss([[1.0]], [[sample_time_s / position_gain_v_per_m]],
                          [[self.integral_gain_v_per_m_s]], [[0.0]], sample_time_s)


#: Eq. 22 and the K_I of §IV.
PAPER_LQG = StateFeedback((9.979e3, 29.686, 0.073), 1.03e6)

#: Diagonal weights of eq. 19 on (x [m], v [m/s], i [A], xi [m s]) with R_J = 1 V^-2
#: for which ``lqr`` returns the paper's gains to four digits.  The paper defers
#: its weights to its reference [4]; these were found by solving the inverse
#: problem (four gains, four diagonal weights) and are the lab's defaults.
#: Read as Bryson's rule (q = 1 / largest acceptable value^2) they say:
#: 0.39 mm of position, 0.17 m/s, 12 A of control current, 0.95 µm s of
#: integrated error, 1 V of amplifier input.
PAPER_LQR_WEIGHTS = (6.6455e6, 34.698, 6.7341e-3, 1.1117e12)


def integral_augmented_model(rig: BearingAxis = RIG) -> tuple[np.ndarray, np.ndarray]:
    """Discrete model (eq. 1, 3-4) augmented by the integral of the position
    error, state (x, v, i, xi), input i_ref [V]:

        [s_{k+1} ]   [ A       0 ] [s_k ]   [B]
        [xi_{k+1}] = [-T e_1^T 1 ] [xi_k] + [0] u_k     (+ T r_k in the last row)
    """
    model = rig.discrete_model(0.0)
    A, B = np.asarray(model.A), np.asarray(model.B)[:, :1]
    T = rig.sample_time_s
    A_aug = np.zeros((4, 4))
    A_aug[:3, :3], A_aug[3, 0], A_aug[3, 3] = A, -T, 1.0
    return A_aug, np.vstack([B, [[0.0]]])


def lqr(state_weights, control_weight: float, rig: BearingAxis = RIG) -> StateFeedback:
    """Discrete LQR with integral action, eq. 19-21, by python-control's ``dlqr``.

    Parameters
    ----------
    state_weights : sequence of 4 floats
        Diagonal of Q_J for (x [1/m^2], v [s^2/m^2], i [1/A^2], xi [1/(m s)^2]).
    control_weight : float
        R_J [1/V^2] on u = i_ref.

    Returns the regulator u = -K s + K_I xi, i.e. dlqr's gain (K, -K_I).
    """
    A_aug, B_aug = integral_augmented_model(rig)
    gain, _, _ = control.dlqr(A_aug, B_aug, np.diag(state_weights), [[control_weight]])
    gain = np.asarray(gain)[0]
    return StateFeedback(tuple(float(g) for g in gain[:3]), float(-gain[3]))


def gain_deviation(designed: StateFeedback, printed: StateFeedback) -> float:
    """Largest relative difference between two regulators' four gains (K, K_I)."""
    a = np.array([*designed.state_gain, designed.integral_gain_v_per_m_s])
    b = np.array([*printed.state_gain, printed.integral_gain_v_per_m_s])
    return float(np.max(np.abs(a / b - 1.0)))
