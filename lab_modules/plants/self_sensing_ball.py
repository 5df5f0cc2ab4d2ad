"""Paper 001 (Glück, Kemmetmüller, Kugi, Tump, VDI Mechatronik 2011): the
ferrite ball under a ferrite core with one coil, driven by a full bridge.

Reluctance model eq. 1-2 (core ``R_fc`` in series with the leakage ``R_l``
parallel to gap ``R_s(s)`` plus ball ``R_fo``), inductance L(s) = N²/R(s),
coil eq. 3-4 (dψ/dt = v − R i with ψ = L(s) i, which contains the motion
term −∂L/∂s w i of eq. 4), magnetic force f = ½ i² ∂L/∂s (co-energy).

The paper gives only v_bat = 11.4 V, ī = 1.5 A and the operating points
4 mm and 6 mm.  The geometry below is the lab's choice, made so that the
mean of the two equilibrium currents is the paper's ī = 1.5 A:
N = 600 turns, μr = 2000 (ferrite core and ball), core path 80 mm ×
2.0e-4 m², ball path 30 mm × 3.0e-4 m², effective gap area 7.0e-5 m²,
leakage reluctance 1.5e7 H⁻¹, coil 2.5 Ω, ball 0.14 kg.  That gives
L(4 mm) = 31.466 mH, L(6 mm) = 28.901 mH and equilibrium currents
1.196 A and 1.791 A.  The leakage path keeps L finite as the gap opens,
as in a real coil; its size makes the gap still dominate (R_s(4 mm) =
4.5e7 H⁻¹ against R_l = 1.5e7 H⁻¹).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

MU0 = 4e-7 * math.pi          # permeability of free space [H/m]
GRAVITY = 9.81                # [m/s²]


@dataclass(frozen=True)
class SelfSensingBall:
    """Geometry and electrical data of the rig (SI units; see the module docstring)."""

    turns: float = 600.0
    relative_permeability: float = 2000.0
    core_length_m: float = 0.080
    core_area_m2: float = 2.0e-4
    ball_length_m: float = 0.030
    ball_area_m2: float = 3.0e-4
    gap_area_m2: float = 7.0e-5
    leakage_reluctance_per_h: float = 1.5e7
    coil_resistance_ohm: float = 2.5
    ball_mass_kg: float = 0.14
    battery_voltage_v: float = 11.4             # paper §4.2

    @property
    def core_reluctance_per_h(self) -> float:
        """Eq. 1: R_fc = l_fc / (μ0 μr A_fc)."""
        return self.core_length_m / (MU0 * self.relative_permeability * self.core_area_m2)

    @property
    def ball_reluctance_per_h(self) -> float:
        """Eq. 1: R_fo = l_fo / (μ0 μr A_fo)."""
        return self.ball_length_m / (MU0 * self.relative_permeability * self.ball_area_m2)

    @property
    def gap_reluctance_slope_per_h_m(self) -> float:
        """Eq. 1: ∂R_s/∂s = 1 / (μ0 A_s)."""
        return 1.0 / (MU0 * self.gap_area_m2)

    def constants(self) -> np.ndarray:
        """(N, R_fc, R_fo, R_l, ∂R_s/∂s) for the compiled functions below."""
        return np.array([self.turns, self.core_reluctance_per_h, self.ball_reluctance_per_h,
                         self.leakage_reluctance_per_h, self.gap_reluctance_slope_per_h_m])

    def inductance_h(self, gap_m):
        """L(s) = N² / R(s), eq. 2."""
        return inductance(np.asarray(gap_m, dtype=float), self.constants())

    def inductance_slope_h_per_m(self, gap_m):
        """∂L/∂s (negative: the inductance falls as the gap opens)."""
        return inductance_slope(np.asarray(gap_m, dtype=float), self.constants())

    def gap_m(self, inductance_h):
        """Eq. 2 solved for s: the air gap that has inductance L."""
        return gap_from_inductance(np.asarray(inductance_h, dtype=float), self.constants())

    def equilibrium_current_a(self, gap_m):
        """The current whose force ½ i² |∂L/∂s| carries the ball's weight."""
        return np.sqrt(2.0 * self.ball_mass_kg * GRAVITY / np.abs(self.inductance_slope_h_per_m(gap_m)))

    def position_sensitivity_m_per_h(self, inductance_h):
        """|∂s/∂L| at inductance L: the factor of eq. 32,
        (∂R_s/∂s)⁻¹ N² R_l² / (N² − (R_l + R_fc) L)²."""
        return position_sensitivity(np.asarray(inductance_h, dtype=float), self.constants())


RIG = SelfSensingBall()


@njit(cache=True, nogil=True)
def inductance(gap_m, c):
    """L(s) = N² / (R_fc + R_l (R_s + R_fo) / (R_l + R_s + R_fo)), eq. 1-2; c = constants()."""
    x = gap_m * c[4] + c[2]
    return c[0] ** 2 / (c[1] + c[3] * x / (c[3] + x))


@njit(cache=True, nogil=True)
def inductance_slope(gap_m, c):
    """∂L/∂s = −N²/R² · R_l²/(R_l + R_s + R_fo)² · ∂R_s/∂s."""
    x = gap_m * c[4] + c[2]
    reluctance = c[1] + c[3] * x / (c[3] + x)
    return -c[0] ** 2 / reluctance**2 * c[3] ** 2 / (c[3] + x) ** 2 * c[4]


@njit(cache=True, nogil=True)
def gap_from_inductance(inductance_h, c):
    """Eq. 2 inverted: R = N²/L, R_s + R_fo = R_l (R − R_fc) / (R_l + R_fc − R), s = (…) / ∂R_s/∂s."""
    reluctance = c[0] ** 2 / inductance_h
    x = c[3] * (reluctance - c[1]) / (c[3] + c[1] - reluctance)
    return (x - c[2]) / c[4]


@njit(cache=True, nogil=True)
def position_sensitivity(inductance_h, c):
    """|∂s/∂L| of eq. 32: (∂R_s/∂s)⁻¹ N² R_l² / (N² − (R_l + R_fc) L)²."""
    return c[0] ** 2 * c[3] ** 2 / (c[0] ** 2 - (c[3] + c[1]) * inductance_h) ** 2 / c[4]
