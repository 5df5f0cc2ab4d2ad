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
* Eq. 2.32 is garbled in the text; the lab follows the paper's controller
  code (App. G), which is eq. 2.23 with v = -k (z - z_ref) + y_R''' (eq. 2.30).
* The lead-lag baseline (§3.5, Fig. 3.22) comes from an earlier project
  whose values the paper does not give; ``LEAD_LAG`` is the lab's own design
  for the same plant (see its docstring).
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


# -- exact feedback linearisation (§2.4, App. E, G) --------------------------------

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


# -- the linear baseline (§3.5, Fig. 3.22) --------------------------------------

@dataclass(frozen=True)
class LeadLag:
    """Lead-lag position controller on the measured gap, u = u_0 + C(s) (x1 - y_R).

    C(s) = K (s + z_1)(s + z_2)/(s + p_lead)^2 * (s + z_lag)/(s + p_lag), Tustin at dt.

    The paper's lead-lag (Fig. 3.22, from its reference [16]) has no published
    values.  This one is designed for Table 3.1's plant linearised at 14.8 mm:
    unstable pole sqrt(2g/x0) = 36.4 rad/s, coil pole R/L = 42.4 rad/s, three
    more poles than zeros, hence two lead zeros (20 and 40 rad/s, below and at
    the plant poles) over a double pole at 400 rad/s.  K = 4e5 V/m places the
    closed-loop poles at -560, -117 +- 96j, -40 and -4.2 +- 6.9j rad/s.  The lag
    (zero 3, pole 0.3 rad/s) raises the low-frequency gain tenfold, so a
    constant disturbance leaves a small static offset, not none, as on the
    hardware (§3.7.1).
    """

    gain_v_per_m: float = 4e5
    lead_zeros_rad_per_s: tuple[float, float] = (20.0, 40.0)
    lead_pole_rad_per_s: float = 400.0
    lag_zero_rad_per_s: float = 3.0
    lag_pole_rad_per_s: float = 0.3

    def transfer_function(self) -> control.TransferFunction:
        s = control.tf("s")
        z1, z2 = self.lead_zeros_rad_per_s
        return (self.gain_v_per_m * (s + z1) * (s + z2) / (s + self.lead_pole_rad_per_s) ** 2
                * (s + self.lag_zero_rad_per_s) / (s + self.lag_pole_rad_per_s))

    def discrete(self, sample_time_s: float) -> control.StateSpace:
        return control.ss(control.c2d(self.transfer_function(), sample_time_s, method="tustin"))


LEAD_LAG = LeadLag()
