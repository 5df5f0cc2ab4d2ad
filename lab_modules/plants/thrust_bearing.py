"""The 281 kg axial (thrust) magnetic bearing of paper 003 (Jiang, Su, Wang).

One axial degree of freedom: a thrust collar on the rotor between two stator
halves in differential drive (Fig. 1-2), with bias current i0 and control
current i_x.  Table 1 gives the machine; eq. 2 the force of the two magnets,
eq. 4 its linearisation, eq. 7 the state equations in (x, v) and eq. 9-11
their second-order Taylor discretisation at T = 0.1 ms.  §3.1 gives the
identified current loop G(s) between the current command and the coil
current.

Sign convention (eq. 4): f_mag ≈ k_i i_x − k_x x with k_x = −4594.1 N/mm, so
−k_x x = +|k_x| x is the destabilising negative stiffness; x > 0 moves the
collar towards the magnet that i_x > 0 strengthens.

Not in the paper, chosen here (and stated in the worksheet):

* bias current i0 = |k_x| x0 / k_i = 0.670 A and force constant
  k_f = k_i x0² / (4 i0) = 1.08e-3 N m²/A²: the only values for which eq. 4's
  k_i = 4 k_f i0 / x0² and k_x = −4 k_f i0² / x0³ give Table 1's numbers;
* the touchdown bearing stops the collar at ±0.75 mm (the paper's start
  X0 = [−0.75 mm, 0] lies on it);
* because that clearance equals the magnetic gap, the nonlinear law eq. 2
  would divide by zero on the stop: it is evaluated with gaps no smaller than
  ``MIN_MAGNETIC_GAP_M`` (the non-magnetic layer on a real pole face), and a
  coil cannot carry negative current, so each magnet's current is clipped at 0;
* the machine is horizontal (§3.2: "卧式", a horizontal prototype), so gravity
  does not act on this axis; ``gravity_m_per_s2`` offers a vertical variant.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import control
import numpy as np
import scipy.linalg
from numba import njit

#: §3.1: identified current loop, coil current over current command.
CURRENT_LOOP_NUMERATOR = (0.1034, 2234.0, 7.237e5)
CURRENT_LOOP_DENOMINATOR = (1.0, 2713.0, 7.43e5)
#: §3: P0 as printed, states (x [m], v [m/s]).
PAPER_P0 = np.array([[8.37e-16, 1.67e-11], [1.67e-11, 3.34e-7]])
#: The nonlinear law's smallest gap (not in the paper): a tenth of the nominal gap.
MIN_MAGNETIC_GAP_M = 0.075e-3
GRAVITY_M_PER_S2 = 9.81


@dataclass(frozen=True)
class ThrustBearing:
    """Table 1 of paper 003 in SI units.

    ``displacement_stiffness_n_per_m`` keeps the paper's sign (k_x < 0, eq. 4)."""

    mass_kg: float = 281.0
    gap_m: float = 0.75e-3                                # x0, nominal air gap
    current_stiffness_n_per_a: float = 5143.0             # k_i
    displacement_stiffness_n_per_m: float = -4594.1e3     # k_x = −4594.1 N/mm
    current_limit_a: float = 10.0
    sample_time_s: float = 0.1e-3                         # §3: T = 0.1 ms
    touchdown_clearance_m: float = 0.75e-3                # X0 = −0.75 mm lies on the stop

    @property
    def negative_stiffness_n_per_m(self) -> float:
        """|k_x|: the force per metre that pulls the collar away from the centre."""
        return -self.displacement_stiffness_n_per_m

    @property
    def bias_current_a(self) -> float:
        """i0 = |k_x| x0 / k_i (eq. 4 solved for i0; not printed in the paper)."""
        return self.negative_stiffness_n_per_m * self.gap_m / self.current_stiffness_n_per_a

    @property
    def force_constant_n_m2_per_a2(self) -> float:
        """k_f = k_i x0² / (4 i0) (eq. 1, 4; not printed in the paper)."""
        return self.current_stiffness_n_per_a * self.gap_m**2 / (4.0 * self.bias_current_a)

    @property
    def open_loop_pole_rad_per_s(self) -> float:
        """sqrt(|k_x| / m): the unstable pole of eq. 7 (the other is its mirror)."""
        return float(np.sqrt(self.negative_stiffness_n_per_m / self.mass_kg))

    @property
    def critical_proportional_gain_a_per_m(self) -> float:
        """Kp below which the net stiffness k_i Kp − |k_x| is negative (loop unstable)."""
        return self.negative_stiffness_n_per_m / self.current_stiffness_n_per_a

    def continuous_model(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Eq. 7: A, B (current i_x [A]) and G (force f_dis [N]) for the state (x [m], v [m/s])."""
        m = self.mass_kg
        A = np.array([[0.0, 1.0], [-self.displacement_stiffness_n_per_m / m, 0.0]])
        B = np.array([0.0, self.current_stiffness_n_per_a / m])
        G = np.array([0.0, 1.0 / m])
        return A, B, G

    def taylor_discretisation(self, sample_time_s: float | None = None):
        """Eq. 9-11: Φ = I + AT + (AT)²/2, B_d = (TI + AT²/2) B, G_d = (TI + AT²/2) G (copies)."""
        T = self.sample_time_s if sample_time_s is None else sample_time_s
        return tuple(M.copy() for M in _taylor(self, T))

    def exact_discretisation(self, sample_time_s: float | None = None):
        """Φ = e^{AT}, B_d and G_d = ∫_0^T e^{At} dt (B, G) by one matrix exponential (inputs held; copies)."""
        T = self.sample_time_s if sample_time_s is None else sample_time_s
        return tuple(M.copy() for M in _exact(self, T))

    def magnetic_force_n(self, control_current_a, x_m):
        """Eq. 2: f = k_f [(i0 + i_x)²/(x0 − x)² − (i0 − i_x)²/(x0 + x)²], with each coil's
        current clipped at 0 and each gap at ``MIN_MAGNETIC_GAP_M`` (module docstring)."""
        i0, x0, k_f = self.bias_current_a, self.gap_m, self.force_constant_n_m2_per_a2
        upper = np.maximum(i0 + np.asarray(control_current_a), 0.0)
        lower = np.maximum(i0 - np.asarray(control_current_a), 0.0)
        return k_f * (upper**2 / np.maximum(x0 - np.asarray(x_m), MIN_MAGNETIC_GAP_M) ** 2
                      - lower**2 / np.maximum(x0 + np.asarray(x_m), MIN_MAGNETIC_GAP_M) ** 2)

    def linear_force_n(self, control_current_a, x_m):
        """Eq. 4: f ≈ k_i i_x − k_x x."""
        return (self.current_stiffness_n_per_a * np.asarray(control_current_a)
                - self.displacement_stiffness_n_per_m * np.asarray(x_m))

    def force_constants(self) -> np.ndarray:
        """(m, k_i, |k_x|, i0, k_f, x0, smallest gap) for the compiled loop."""
        return np.array([self.mass_kg, self.current_stiffness_n_per_a, self.negative_stiffness_n_per_m,
                         self.bias_current_a, self.force_constant_n_m2_per_a2, self.gap_m,
                         MIN_MAGNETIC_GAP_M])


@njit(cache=True, nogil=True)
def force_and_stiffness(x_m, control_current_a, constants):
    """Eq. 2 at (i_x, x): the force f [N] and its slope ∂f/∂x [N/m] at the current held, for the
    compiled loop; ``constants`` = ``ThrustBearing.force_constants``.  Each coil's current is clipped
    at 0 and each gap at the smallest gap (``magnetic_force_n``); a clipped gap adds no slope.
    At the centre ∂f/∂x = 4 k_f i0² / x0³ = |k_x| (eq. 4)."""
    i0, k_f, x0, smallest_gap = constants[3], constants[4], constants[5], constants[6]
    upper, lower = max(i0 + control_current_a, 0.0), max(i0 - control_current_a, 0.0)
    gap_upper, gap_lower = x0 - x_m, x0 + x_m
    slope = 0.0
    if gap_upper > smallest_gap:
        pull_upper = k_f * upper * upper / (gap_upper * gap_upper)     # f+ = k_f (i0 + i)² / (x0 − x)²
        slope += 2.0 * pull_upper / gap_upper                          # ∂f+/∂x = 2 f+ / (x0 − x)
    else:
        pull_upper = k_f * upper * upper / (smallest_gap * smallest_gap)
    if gap_lower > smallest_gap:
        pull_lower = k_f * lower * lower / (gap_lower * gap_lower)     # f− = k_f (i0 − i)² / (x0 + x)²
        slope += 2.0 * pull_lower / gap_lower                          # −∂f−/∂x = 2 f− / (x0 + x)
    else:
        pull_lower = k_f * lower * lower / (smallest_gap * smallest_gap)
    return pull_upper - pull_lower, slope


@lru_cache(maxsize=16)
def _taylor(bearing: ThrustBearing, T: float):
    A, B, G = bearing.continuous_model()
    AT = A * T
    integral = T * np.eye(2) + A * T**2 / 2.0
    return np.eye(2) + AT + AT @ AT / 2.0, integral @ B, integral @ G


@lru_cache(maxsize=16)
def _exact(bearing: ThrustBearing, T: float):
    A, B, G = bearing.continuous_model()
    M = np.zeros((4, 4))
    M[:2, :2], M[:2, 2], M[:2, 3] = A, B, G
    E = scipy.linalg.expm(M * T)
    return E[:2, :2], E[:2, 2].copy(), E[:2, 3].copy()


def current_loop() -> control.TransferFunction:
    """§3.1: G(s) = (0.1034 s² + 2234 s + 7.237e5) / (s² + 2713 s + 7.43e5), command -> coil current."""
    return control.tf(CURRENT_LOOP_NUMERATOR, CURRENT_LOOP_DENOMINATOR)


def discrete_current_loop(sample_time_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """G(s) as a discrete state space for a held command (ZOH): (A_g, B_g, C_g, D_g) (copies)."""
    A, B, C, D = _discrete_current_loop(sample_time_s)
    return A.copy(), B.copy(), C.copy(), D


@lru_cache(maxsize=16)
def _discrete_current_loop(sample_time_s: float):
    d = control.c2d(control.ss(current_loop()), sample_time_s, method="zoh")
    return (np.asarray(d.A, dtype=float), np.asarray(d.B, dtype=float).ravel(),
            np.asarray(d.C, dtype=float).ravel(), float(np.asarray(d.D).item()))


#: Table 1.
TABLE_1 = ThrustBearing()
