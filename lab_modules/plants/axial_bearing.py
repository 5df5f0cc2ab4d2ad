"""The axial magnetic bearing of paper 002 (Li, Kästner, Worlitz, TU Ilmenau 2014):
one rotor axis between two electromagnets driven in differential mode.

Force law (the paper's eq. 1, its symbols lost in the text, reconstructed as the
standard differential bearing with the force constant of Table 1):

    F_Magnet(i, x) = k_M [ (i0 + i)² / (s0 - x)² - (i0 - i)² / (s0 + x)² ]        (1)

with k_M = μ0 A N² / 4 = 6.7 N·mm²/A², s0 = 2 mm, i0 = 1.5 A (Table 1).  Table 1
also lists a total air gap of 5 mm, which is not 2·s0; s0 = 2 mm is what
reproduces the paper's Tables 4 and 5, so the lab uses it.  Rotor: m = 0.518 kg
at 0 rpm; the axis is vertical, eq. 2: m ẍ = F_Magnet + F_St - m g.

Everything here is in SI units (m, A, N); the paper's tables are in A and mm
(``N_PER_MM``).  Centre values (eq. 5-6): k_i = 4 k_M i0 / s0² = 10.05 N/A,
k_s = 4 k_M i0² / s0³ = 7.5375 N/mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

N_PER_MM = 1e3                      # 1 N/mm = 1000 N/m
MM = 1e-3


@dataclass(frozen=True)
class AxialBearing:
    """Table 1 of paper 002, in SI units."""

    mass_kg: float = 0.518
    k_magnet_n_m2_per_a2: float = 6.7e-6      # 6.7 N·mm²/A²
    nominal_gap_m: float = 2e-3               # s0
    bias_current_a: float = 1.5               # i0
    gravity_m_per_s2: float = 9.81

    @property
    def weight_n(self) -> float:
        return self.mass_kg * self.gravity_m_per_s2

    def force_n(self, current_a, position_m, k_magnet=None):
        """Eq. 1 (array-friendly)."""
        k = self.k_magnet_n_m2_per_a2 if k_magnet is None else k_magnet
        return magnet_force(np.asarray(current_a, float), np.asarray(position_m, float), k,
                            self.nominal_gap_m, self.bias_current_a)

    def tangent_factors(self, current_a, position_m):
        """(k_i [N/A], k_s [N/m]): the partial derivatives of eq. 1 (eq. 3-4) at (i, x)."""
        return tangent_factors(np.asarray(current_a, float), np.asarray(position_m, float),
                               self.k_magnet_n_m2_per_a2, self.nominal_gap_m, self.bias_current_a)

    def centre_factors(self) -> tuple[float, float]:
        """(k_i [N/A], k_s [N/m]) at x = 0, i = 0 (eq. 5-6)."""
        k, s0, i0 = self.k_magnet_n_m2_per_a2, self.nominal_gap_m, self.bias_current_a
        return 4 * k * i0 / s0**2, 4 * k * i0**2 / s0**3


AXIAL = AxialBearing()

#: The operating-point grid of Tables 2 and 3 (signs lost in the text, restored).
GRID_CURRENTS_A = np.array([-1.5, -0.75, 0.0, 0.75, 1.5])
GRID_POSITIONS_M = np.array([-0.5, -0.25, 0.0, 0.25, 0.5]) * MM

#: Table 4 as printed: k_i [N/A]; rows x = -0.5 ... 0.5 mm, columns i = -1.5 ... 1.5 A.
TABLE_4_KI_N_PER_A = np.array([
    [7.14, 8.47, 12.15, 9.35, 8.74],
    [9.47, 9.58, 10.53, 9.69, 9.65],
    [10.05, 10.05, 10.05, 10.05, 10.05],
    [9.66, 9.69, 10.53, 9.58, 9.48],
    [8.75, 9.35, 12.15, 8.45, 7.14]])

#: Table 5 as printed: k_s [N/mm]; same rows and columns.
TABLE_5_KS_N_PER_MM = np.array([
    [32.16, 16.23, 8.57, 6.53, 6.94],
    [21.89, 12.57, 7.78, 7.21, 10.30],
    [15.08, 9.42, 7.53, 9.42, 15.08],
    [10.30, 7.21, 7.78, 12.57, 21.89],
    [6.95, 6.53, 8.57, 16.23, 32.16]])


@njit(cache=True, nogil=True)
def magnet_force(current_a, position_m, k_magnet, s0, i0):
    """Eq. 1 [N] (scalars or arrays)."""
    return k_magnet * ((i0 + current_a) ** 2 / (s0 - position_m) ** 2
                       - (i0 - current_a) ** 2 / (s0 + position_m) ** 2)


@njit(cache=True, nogil=True)
def force_shape(current_a, position_m, s0, i0):
    """φ(i, x) = F_Magnet / k_M [A²/m²]: the regressor of the SISO ADALINE (F = k_M φ)."""
    return (i0 + current_a) ** 2 / (s0 - position_m) ** 2 - (i0 - current_a) ** 2 / (s0 + position_m) ** 2


@njit(cache=True, nogil=True)
def tangent_factors(current_a, position_m, k_magnet, s0, i0):
    """(∂F/∂i [N/A], ∂F/∂x [N/m]) of eq. 1 at (i, x)."""
    lower, upper = s0 - position_m, s0 + position_m
    k_i = 2 * k_magnet * ((i0 + current_a) / lower**2 + (i0 - current_a) / upper**2)
    k_s = 2 * k_magnet * ((i0 + current_a) ** 2 / lower**3 + (i0 - current_a) ** 2 / upper**3)
    return k_i, k_s
