"""The lead-lag baseline controller of the maglev ball (paper 004, §3.5, Fig. 3.22).

It comes from an earlier project whose values the paper does not give;
``LEAD_LAG`` is the lab's own design for the same plant (see its docstring).
"""

from __future__ import annotations

from dataclasses import dataclass

import control


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
