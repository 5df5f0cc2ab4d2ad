"""One radial axis of the test rig's active magnetic bearing.

Source: Schuhmann, Hofmann, Werner, *Adaptive Linear and Extended Kalman Filter
applied to AMB with Collocated Position Measuring* (paper 000), §II-III and the
Appendix ("Test rig parameters").  Everything here is in SI units.

Values the paper leaves out:

* Air gap ``delta0_m`` and premagnetising current ``i0_a`` are *derived*, not
  chosen.  Linearising the force law eq. 10 at the centre gives
  k_i = 4 c_f i0 / delta0**2 and k_x = 4 c_f i0**2 cos(alpha) / delta0**3, so
  k_x / k_i = i0 cos(alpha) / delta0.  With the appendix's c_f, alpha, k_i and
  k_x this yields delta0 = 0.460 mm (inside the rated 0.3 ... 0.7 mm) and
  i0 = 3.10 A.
* The amplifier's current limit is the control current that produces the rated
  force: F_r / k_i = 2400 N / 128.6 N/A = 18.7 A.
* The position sensor's lag T_mx (eq. 12) is chosen in the exercises; see
  ``DEFAULT_SENSOR_LAG_S``.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import control
import numpy as np

#: T_mx of eq. 12.  The paper gives no value.  The capacitive sensor is read by
#: an in-phase rectifier behind a *narrow-band* bandpass (§I), whose envelope
#: bandwidth is a few times the loop's fastest closed-loop mode (about 210 Hz
#: for the paper's PID): 800 Hz, i.e. T_mx = 1 / (2 pi 800 Hz) = 200 µs.  A lag
#: this large is why the paper carries x_d as a state (eq. 12-13) and why its
#: steady-state linear filter is of fourth order (§IV, Fig. 7).
DEFAULT_SENSOR_LAG_S = 200e-6


@dataclass(frozen=True)
class BearingAxis:
    """Appendix parameters of paper 000 (one bearing axis)."""

    rotor_mass_kg: float = 25.0            # mass of test rotor
    equivalent_mass_kg: float = 21.5       # m, eq. 3
    ki_n_per_a: float = 128.6              # k_i, force-current factor, eq. 3
    kx_n_per_m: float = 800310.0           # k_x, force-position factor, eq. 3
    amplifier_gain_a_per_v: float = 5.0    # K_a, eq. 4
    amplifier_lag_s: float = 400e-6        # T_a, eq. 4
    position_sensor_gain_v_per_m: float = 20e-3 / 1e-6   # K_mx = 20 mV/µm
    current_sensor_gain_v_per_a: float = 0.2             # K_mi
    force_factor_n_m2_per_a2: float = 2.1935e-6          # c_f, eq. 10
    pole_angle_rad: float = np.pi / 8                    # alpha, eq. 10
    rated_force_n: float = 2400.0                        # F_r
    sample_time_s: float = 50e-6                         # T (all algorithms)

    # -- derived quantities (see module docstring) ---------------------------
    @property
    def delta0_m(self) -> float:
        """Nominal air gap delta0 [m] that makes eq. 10 reproduce k_i and k_x."""
        i0_over_delta0 = self.kx_n_per_m / (self.ki_n_per_a * np.cos(self.pole_angle_rad))
        i0_over_delta0_sq = self.ki_n_per_a / (4.0 * self.force_factor_n_m2_per_a2)
        return i0_over_delta0 / i0_over_delta0_sq

    @property
    def i0_a(self) -> float:
        """Related premagnetising current i0 [A] that makes eq. 10 reproduce k_i and k_x."""
        return self.ki_n_per_a * self.delta0_m**2 / (4.0 * self.force_factor_n_m2_per_a2)

    @property
    def current_limit_a(self) -> float:
        """Amplifier control-current limit [A]: the current giving the rated force F_r."""
        return self.rated_force_n / self.ki_n_per_a

    @property
    def touchdown_m(self) -> float:
        """Displacement [m] counted as touchdown: the rotor beyond the nominal air gap."""
        return self.delta0_m

    def magnetic_force(self, x_m, i_a):
        """Bearing force f_m(x, i) [N] of one differential magnet pair, eq. 10."""
        return magnetic_force(x_m, i_a, self.force_factor_n_m2_per_a2, self.i0_a,
                              self.delta0_m, np.cos(self.pole_angle_rad))

    def local_factors(self, x_m: float, i_a: float) -> tuple[float, float]:
        """Analytic derivatives (k_x [N/m], k_i [N/A]) of eq. 10 at (x, i)."""
        c, i0, d0 = self.force_factor_n_m2_per_a2, self.i0_a, self.delta0_m
        ca = np.cos(self.pole_angle_rad)
        gap_plus, gap_minus = d0 - x_m * ca, d0 + x_m * ca
        kx = 2 * c * ca * ((i0 + i_a) ** 2 / gap_plus**3 + (i0 - i_a) ** 2 / gap_minus**3)
        ki = 2 * c * ((i0 + i_a) / gap_plus**2 + (i0 - i_a) / gap_minus**2)
        return kx, ki

    # -- linear model, eq. 3-4 and 12 ----------------------------------------
    def continuous_model(self, sensor_lag_s: float = 0.0) -> control.StateSpace:
        """Linear model of eq. 3-4, with the position sensor's lag eq. 12 when
        ``sensor_lag_s`` (T_mx) > 0.

        States  (x [m], v [m/s], i [A]) and, with a lag, x_d [m] (eq. 13);
        inputs  (i_ref [V], f_z [N]): amplifier reference, disturbance force (eq. 11);
        outputs (K_mx x_d [V], K_mi i [V]), with x_d = x when there is no lag.
        """
        m, Ta, Ka = self.equivalent_mass_kg, self.amplifier_lag_s, self.amplifier_gain_a_per_v
        n = 4 if sensor_lag_s > 0 else 3
        A = np.zeros((n, n))
        A[0, 1] = 1.0
        A[1, 0], A[1, 2] = self.kx_n_per_m / m, self.ki_n_per_a / m
        A[2, 2] = -1.0 / Ta
        B = np.zeros((n, 2))
        B[2, 0], B[1, 1] = Ka / Ta, 1.0 / m
        C = np.zeros((2, n))
        C[0, n - 1 if n == 4 else 0] = self.position_sensor_gain_v_per_m
        C[1, 2] = self.current_sensor_gain_v_per_a
        if n == 4:
            A[3, 0], A[3, 3] = 1.0 / sensor_lag_s, -1.0 / sensor_lag_s
        return control.ss(A, B, C, np.zeros((2, 2)))

    @functools.lru_cache(maxsize=64)  # noqa: B019 (RIG lives as long as the process) sliders revisit lags; do not mutate
    def discrete_model(self, sensor_lag_s: float = 0.0) -> control.StateSpace:
        """Zero-order-hold discretisation at T = 50 µs: the A, B, C of eq. 1."""
        return control.c2d(self.continuous_model(sensor_lag_s), self.sample_time_s, method="zoh")


def magnetic_force(x_m, i_a, c_f, i0_a, delta0_m, cos_alpha):
    """Eq. 10: f_m = c_f [ (i0+i)^2/(delta0 - x cos a)^2 - (i0-i)^2/(delta0 + x cos a)^2 ]."""
    return c_f * ((i0_a + i_a) ** 2 / (delta0_m - x_m * cos_alpha) ** 2
                  - (i0_a - i_a) ** 2 / (delta0_m + x_m * cos_alpha) ** 2)


RIG = BearingAxis()
