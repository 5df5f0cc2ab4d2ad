"""Exact feedback linearisation of the maglev ball (paper 004, §2.4, App. B-E, G).

The ball's model (``plants.maglev_ball``) is input-output linearised by
u = (v - L_f^3 h) / (L_g L_f^2 h) (eq. 2.23) into a chain of three
integrators (eq. 2.24), stabilised by pole placement (eq. 2.26-2.28).
Eq. 2.32 is garbled in the text; the lab follows the paper's controller code
(App. G), which is eq. 2.23 with v = -k (z - z_ref) + y_R''' (eq. 2.30).
"""

from __future__ import annotations

import control
import numba
import numpy as np

from lab_modules.plants.maglev_ball import TABLE_3_1, MaglevPlant

_JIT = {"nogil": True, "cache": True}


def brunovsky_chain() -> control.StateSpace:
    """The linearised system of eq. 2.24: a chain of three integrators z1 -> z2 -> z3 <- v."""
    A = np.diag([1.0, 1.0], k=1)
    B = np.array([[0.0], [0.0], [1.0]])
    return control.ss(A, B, np.array([[1.0, 0.0, 0.0]]), 0.0)


def feedback_gain(poles_rad_per_s) -> np.ndarray:
    """State-feedback gain k of eq. 2.28 by pole placement on eq. 2.24 (python-control).

    The paper uses the Bass-Gura formula (eq. 2.26); ``control.place`` gives
    the same k.  Poles -60, -80, -100 rad/s -> k = [480000, 18800, 240].
    """
    chain = brunovsky_chain()
    return np.asarray(control.place(chain.A, chain.B, list(poles_rad_per_s))).ravel()


def linearising_coordinates(x, plant: MaglevPlant = TABLE_3_1) -> np.ndarray:
    """z = Phi(x) of eq. 2.21: (position, velocity, acceleration)."""
    x = np.asarray(x, dtype=float)
    C, m, g = plant.force_constant_n_m2_per_a2, plant.mass_kg, plant.gravity_m_per_s2
    return np.array([x[0], x[1], g - C / m * (x[2] / x[0]) ** 2])


#: The controller's singularity guard: the region x1 -> 0, x3 -> 0 where
#: L_g L_f^2 h (eq. 2.17) vanishes.  Estimates below these are clamped before
#: eq. 2.23 is evaluated, and the step is counted as guarded.  Not in the
#: paper (its hardware clamps x3 to [0, 1.25] A, App. F); 1 mm is far outside
#: the sensor range, 10 mA is 1 % of the operating current.
GUARD_GAP_M = 1e-3
GUARD_CURRENT_A = 0.01


@numba.njit(**_JIT)
def linearising_control(x_hat, reference, k, p):
    """Coil voltage of the tracking controller, eq. 2.21-2.23 and 2.30 (paper code App. G).

    reference = (y_R, y_R', y_R'', y_R''') [m, m/s, m/s^2, m/s^3]::

        z   = (x1, x2, g - (C/m)(x3/x1)^2)                          (2.21)
        v   = -k1 (z1 - y_R) - k2 (z2 - y_R') - k3 (z3 - y_R'') + y_R'''
        u   = (v - L_f^3 h) / L_g L_f^2 h                           (2.23, 2.30)
        L_f^3 h   = 2 (C/m) x3^2 x2 / x1^3 + 2 (C/m)(R/L) x3^2 / x1^2
        L_g L_f^2 h = -2 C x3 / (m L x1^2)                           (2.17)

    Returns (u [V], guarded): ``guarded`` is True when the estimate lay in the
    singular region and was clamped (``GUARD_GAP_M``, ``GUARD_CURRENT_A``).
    """
    m, L, R, C, g = p[0], p[1], p[2], p[3], p[4]
    x1, x2, x3 = x_hat[0], x_hat[1], x_hat[2]
    guarded = False
    if not x1 >= GUARD_GAP_M:       # also catches NaN
        x1 = GUARD_GAP_M
        guarded = True
    if not x3 >= GUARD_CURRENT_A:
        x3 = GUARD_CURRENT_A
        guarded = True
    z3 = g - C / m * (x3 / x1) ** 2
    lf3h = 2.0 * C / m * x3 * x3 / x1**3 * x2 + 2.0 * C / m * x3 * x3 / x1**2 * R / L
    lglf2h = -2.0 * C / m * x3 / (x1 * x1) / L
    v = -(k[0] * (x1 - reference[0]) + k[1] * (x2 - reference[1])
          + k[2] * (z3 - reference[2])) + reference[3]
    return (v - lf3h) / lglf2h, guarded


def decoupling_gain_v_per_m_s3(gap_m, current_a, plant: MaglevPlant = TABLE_3_1):
    """|1 / L_g L_f^2 h| = m L x1^2 / (2 C x3) (eq. 2.23b): volts per unit of v [m/s^3].

    It grows without bound as x3 -> 0 and vanishes as x1 -> 0: the two edges
    of the region where the transform exists (§2.4.2).
    """
    C, m, L = plant.force_constant_n_m2_per_a2, plant.mass_kg, plant.coil_inductance_h
    return m * L * np.asarray(gap_m) ** 2 / (2.0 * C * np.asarray(current_a))
