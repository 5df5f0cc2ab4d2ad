"""Discrete PID controllers, and the compiled step of any discrete SISO controller.

``pid`` returns a discrete ``control.StateSpace`` mapping the control error
e [V] (reference minus fed-back position, in sensor volts) to the amplifier
reference i_ref [V] (paper 000, §IV); ``setpoint_filter`` is the reference
filter that makes it an I-PD.  The simulation kernels only ever see
matrices, so any discrete SISO controller (PID, lead-lag, the integral part
of an LQG) plugs into the same loop: a kernel takes it as a
``DiscreteController`` bundle and steps it with ``controller_step``.
"""

from __future__ import annotations

from typing import NamedTuple

import control
import numba
import numpy as np


class DiscreteController(NamedTuple):
    """A discrete SISO controller as the compiled loops take it (stepped by ``controller_step``):
    ctrl_{k+1} = A ctrl_k + B e_k,  u_k = C ctrl_k + D e_k, with e and u in the loop's
    units (bearing loops: e [V] -> i_ref [V]; maglev lead-lag: e [m] -> coil voltage [V])."""

    state: np.ndarray   # (n_c,) controller state ctrl, advanced in place [the realisation's own units]
    A: np.ndarray       # (n_c, n_c) state matrix [-]
    B: np.ndarray       # (n_c, 1) input column [state per unit of e]
    C: np.ndarray       # (1, n_c) output row [unit of u per state]
    D: np.ndarray       # (1, 1) feedthrough [unit of u per unit of e]


def pid(gain: float, integral_time_s: float, derivative_time_s: float,
        derivative_filter_s: float, sample_time_s: float) -> control.StateSpace:
    """Discrete PID with a first-order derivative filter (paper 000, §IV).

    C(s) = K (1 + 1/(T_I s) + T_D s / (tau s + 1)),  Tustin-discretised at T.

    The paper's root-locus design is K = 0.65 V/V, T_I = 50 ms, T_D = 3 ms on
    the sensor voltages.  The paper does not give the derivative filter; the
    lab uses tau = T_D / 10 (the textbook N = 10), i.e. 300 µs for T_D = 3 ms:
    a pure derivative would amplify sensor noise without bound.

    Parameters
    ----------
    gain : float
        Proportional gain K [V/V].
    integral_time_s, derivative_time_s : float
        T_I and T_D [s].
    derivative_filter_s : float
        Time constant tau of the derivative filter [s].
    sample_time_s : float
        Sampling time T [s].
    """
    s = control.tf("s")
    continuous = gain * (1 + 1 / (integral_time_s * s)
                         + derivative_time_s * s / (derivative_filter_s * s + 1))
    return control.ss(control.c2d(continuous, sample_time_s, method="tustin"))


def setpoint_filter(integral_time_s: float, derivative_time_s: float, derivative_filter_s: float,
                    sample_time_s: float) -> control.StateSpace:
    """Reference filter that turns the PID into an I-PD (set-point weights b = c = 0).

    An I-PD lets the reference act through the integral term only,

        u = K/(T_I s) (r - y) - K (1 + T_D s / (tau s + 1)) y,

    which is the ordinary PID C(s) acting on F(s) r - y with
    F = C_I / C, C_I = K / (T_I s) its integral part:

        F(s) = (tau s + 1) / ((T_I s + 1)(tau s + 1) + T_I T_D s^2),

    independent of K.  Tustin-discretised like ``pid``, F(z) is exactly
    C_I(z) / C(z) of the discrete PID, so the loop with this filter in front
    is the discrete I-PD.  (Set-point weighting: Åström & Hägglund, *PID
    Controllers*, 1995, §4.4; the lab adds it to test whether the LQG's mild
    step response of paper 000 Fig. 8 comes from its structure, not from its
    optimality.)"""
    s = control.tf("s")
    T_I, T_D, tau = integral_time_s, derivative_time_s, derivative_filter_s
    continuous = (tau * s + 1) / ((T_I * s + 1) * (tau * s + 1) + T_I * T_D * s**2)
    return control.ss(control.c2d(continuous, sample_time_s, method="tustin"))


@numba.njit(inline="always")
def controller_step(e, offset_v, u_limit, ctrl, Ac, Bc, Cc, Dc, work):
    """One sample of a discrete SISO controller (Ac, Bc, Cc, Dc) in a compiled loop.

    Returns the output Cc ctrl + Dc e + offset_v for the error e (e [V] and
    i_ref [V] in the bearing loops), clipped at ±u_limit (the amplifier limit;
    inf: none), and advances the state
    ctrl <- Ac ctrl + Bc e in place (``work``: scratch of ctrl's size).  The
    offset carries what the loop adds to the controller: a state feedback
    -K_s x_hat (eq. 22), a feedforward or an operating point.  Inlined into
    the caller, so it is compiled with the caller's options.  The arrays come in
    one by one: a kernel reads them out of its ``DiscreteController`` once, before its
    loop (an array read out of a bundle inside the loop costs a reference count per sample)."""
    n_c = ctrl.shape[0]
    u = Dc[0, 0] * e + offset_v
    for r in range(n_c):
        u += Cc[0, r] * ctrl[r]
    for r in range(n_c):
        acc = Bc[r, 0] * e
        for c in range(n_c):
            acc += Ac[r, c] * ctrl[c]
        work[r] = acc
    for r in range(n_c):
        ctrl[r] = work[r]
    return min(max(u, -u_limit), u_limit)
