"""The classroom maglev: a steel ball under an electromagnet.

Source: Henley, *Feedback linearized control of a maglev system with a
continuous-discrete extended Kalman filter* (paper 004): model §2.3
(eq. 2.1-2.14), exact feedback linearisation §2.4 and Appendices B-E,
parameters Table 3.1, controller code Appendix G.  SI units throughout.

State x = (x1 gap below the coil [m], x2 velocity [m/s], x3 coil current [A]),
input u = coil voltage [V], output y = x1 (eq. 2.10-2.11)::

    x1' = x2
    x2' = g - (C/m) (x3/x1)^2                 C = L0 x0 / 2   (eq. 2.7)
    x3' = -(R/L) x3 + u/L

Notes on the paper's numbers:

* Table 3.1 prints m = 0.055066 kg, but §3.3 weighs the ball at 0.05506 kg,
  the code (App. F, G) uses 0.05506 kg, and Table 3.1's own plant current
  0.89409 A follows from eq. 2.14 only with 0.05506 kg (0.055066 kg gives
  0.89414 A).  The lab uses 0.05506 kg.
* The paper's Jacobian (App. F, G) has 3 (C/m) x3^2/x1^3 in row 2, column 1;
  the derivative of eq. 2.10 is 2 (C/m) x3^2/x1^3.  The lab uses the
  derivative (checked against finite differences in the tests).
* Feedback linearisation (``controllers.feedback_linearisation``) and the
  lead-lag baseline (``controllers.lead_lag``) act on this plant.
"""

from __future__ import annotations

from dataclasses import dataclass

import control
import numba
import numpy as np

_JIT = {"nogil": True, "cache": True}


@dataclass(frozen=True)
class MaglevPlant:
    """Table 3.1 parameters (paper 004)."""

    mass_kg: float = 0.05506                  # m, levitated steel ball (§3.3; see module docstring)
    coil_inductance_h: float = 0.59           # L_c
    incremental_inductance_h: float = 0.02    # L_0, added by the ball (eq. 2.6)
    coil_resistance_ohm: float = 25.0         # R_c
    gravity_m_per_s2: float = 9.81            # g
    operating_gap_m: float = 0.0148           # x_0 of eq. 2.6: mid sensor range (§3.3)
    sample_time_s: float = 0.001              # dt

    @property
    def force_constant_n_m2_per_a2(self) -> float:
        """C = L_0 x_0 / 2 of eq. 2.7 [N m^2/A^2]."""
        return self.incremental_inductance_h * self.operating_gap_m / 2.0

    def equilibrium_current_a(self, gap_m: float) -> float:
        """Eq. 2.14: x3_0 = x1_0 sqrt(g m / C) (0.894 A at 14.8 mm)."""
        return gap_m * np.sqrt(self.gravity_m_per_s2 * self.mass_kg / self.force_constant_n_m2_per_a2)

    def equilibrium_voltage_v(self, gap_m: float) -> float:
        """Coil voltage that holds the equilibrium current, R_c x3_0 [V]."""
        return self.coil_resistance_ohm * self.equilibrium_current_a(gap_m)

    def constants(self) -> np.ndarray:
        """(m, L_c, R_c, C, g) for the compiled kernels."""
        return np.array([self.mass_kg, self.coil_inductance_h, self.coil_resistance_ohm,
                         self.force_constant_n_m2_per_a2, self.gravity_m_per_s2])

    def linear_model(self, gap_m: float | None = None) -> control.StateSpace:
        """Eq. 2.10 linearised at the equilibrium (eq. 2.13-2.14), u -> x1."""
        gap = self.operating_gap_m if gap_m is None else gap_m
        x0 = np.array([gap, 0.0, self.equilibrium_current_a(gap)])
        A = jacobian(x0, self.constants())
        B = np.array([[0.0], [0.0], [1.0 / self.coil_inductance_h]])
        return control.ss(A, B, np.array([[1.0, 0.0, 0.0]]), 0.0)


TABLE_3_1 = MaglevPlant()


# -- eq. 2.10 and its Jacobian (eq. 2.44), compiled -------------------------------

@numba.njit(**_JIT)
def derivative(x, u, p):
    """Right-hand side of eq. 2.10; p = (m, L_c, R_c, C, g).  Returns a tuple."""
    m, L, R, C, g = p[0], p[1], p[2], p[3], p[4]
    ratio = x[2] / x[0]
    return x[1], g - C / m * ratio * ratio, (-R * x[2] + u) / L


@numba.njit(**_JIT)
def rk4_step(x, u, p, dt, out):
    """One fixed-step RK4 step of eq. 2.10 with u held (the paper's integrator, §3.1.1)."""
    k1 = derivative(x, u, p)
    t = np.empty(3)
    for j in range(3):
        t[j] = x[j] + 0.5 * dt * k1[j]
    k2 = derivative(t, u, p)
    for j in range(3):
        t[j] = x[j] + 0.5 * dt * k2[j]
    k3 = derivative(t, u, p)
    for j in range(3):
        t[j] = x[j] + dt * k3[j]
    k4 = derivative(t, u, p)
    for j in range(3):
        out[j] = x[j] + dt / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])


@numba.njit(**_JIT)
def jacobian(x, p):
    """F = df/dx of eq. 2.10 (eq. 2.44)."""
    m, L, R, C = p[0], p[1], p[2], p[3]
    F = np.zeros((3, 3))
    F[0, 1] = 1.0
    F[1, 0] = 2.0 * C / m * x[2] * x[2] / (x[0] ** 3)
    F[1, 2] = -2.0 * C / m * x[2] / (x[0] ** 2)
    F[2, 2] = -R / L
    return F
