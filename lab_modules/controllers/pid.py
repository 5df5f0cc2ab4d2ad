"""Discrete PID controllers, and the compiled step of any discrete SISO controller.

``pid`` returns a discrete ``control.StateSpace`` mapping the control error
e [V] (reference minus fed-back position, in sensor volts) to the amplifier
reference i_ref [V] (paper 000, §IV).  The simulation kernels only ever see
matrices, so any discrete SISO controller (PID, lead-lag, the integral part
of an LQG) plugs into the same loop; ``controller_step`` is their compiled
step.
"""

from __future__ import annotations

import control
import numba


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


@numba.njit(inline="always")
def controller_step(e, offset_v, u_limit, ctrl, Ac, Bc, Cc, Dc, work):
    """One sample of a discrete SISO controller (Ac, Bc, Cc, Dc) in a compiled loop.

    Returns the output Cc ctrl + Dc e + offset_v for the error e (e [V] and
    i_ref [V] in the bearing loops), clipped at ±u_limit (the amplifier limit;
    inf: none), and advances the state
    ctrl <- Ac ctrl + Bc e in place (``work``: scratch of ctrl's size).  The
    offset carries what the loop adds to the controller: a state feedback
    -K_s x_hat (eq. 22), a feedforward or an operating point.  Inlined into
    the caller, so it is compiled with the caller's options."""
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
