"""Controllers acting on the bearing axis, as discrete LTI systems.

Every controller here is returned as a discrete ``control.StateSpace`` mapping
the control error e [V] (reference minus fed-back position, in sensor volts) to
the amplifier reference i_ref [V].  The simulation kernel only ever sees the
matrices, so any linear controller plugs into the same loop.
"""

from __future__ import annotations

import control


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
