"""What several exercises build from the same sliders.

The controller sliders pid_gain, integral_time_ms, derivative_time_ms and
derivative_filter_us are ``kalman_noise``'s, shared by the exercises that run
the paper's PID (paper 000, §IV).
"""

from __future__ import annotations

from functools import lru_cache

import control
import numpy as np

from lab_modules.controllers.pid import pid
from lab_modules.plants.radial_bearing import RIG

#: ``controllers.pid`` remembered per setting: its Tustin discretisation takes
#: milliseconds, most slider moves leave the gains alone, and the analyses
#: build the same PID for several runs.
_cached_pid = lru_cache(maxsize=128)(pid)


def pid_from_values(values: dict, gain_factor: float = 1.0) -> control.StateSpace:
    """The PID of the controller sliders at the rig's sample time, its gain K times ``gain_factor``."""
    return _cached_pid(values["pid_gain"] * gain_factor, values["integral_time_ms"] * 1e-3,
                       values["derivative_time_ms"] * 1e-3, values["derivative_filter_us"] * 1e-6,
                       RIG.sample_time_s)


def ekf_loop_fields(values: dict) -> dict:
    """The ``radial_axis_ekf_loop.EKFLoopSetup`` fields that the EKF exercises read from the same
    sliders: the PID and its feedback source, the measurement variances R (eq. 16)
    and the plant's noise."""
    return {"controller": pid_from_values(values),
            "use_estimate": values["feedback"] == "estimated",
            "filter_R_diag": np.array([values["filter_r_position"], values["filter_r_current"]]),
            "sensor_noise_m": values["sensor_noise_um"] * 1e-6,
            "current_noise_a": values["current_noise_a"],
            "process_force_n": values["disturbance_force_n"]}


# -- pole names for the pole map (``Exercise.mode_names``) ----------------------------------
def nearest_names(poles_s, named: list[tuple[complex, str]], tolerance: float = 1e-6) -> list[str | None]:
    """For each pole [rad/s] the name of the nearest named pole (or its conjugate) within
    ``tolerance`` × |s|; None where no named pole is that close."""
    out = []
    for p in np.asarray(poles_s, dtype=complex):
        distances = [min(abs(p - q), abs(p - np.conj(q))) for q, _ in named]
        k = int(np.argmin(distances)) if distances else -1
        out.append(named[k][1] if k >= 0 and distances[k] <= tolerance * max(abs(p), 1.0) else None)
    return out


def magnet_plant_names(poles_s, A, body: str, lags: tuple[str, ...]) -> list[str | None]:
    """Names of an open-loop magnet plant's poles [rad/s].  Its states are a position, a
    velocity and first-order lags (coil current, sensor) driven by them but not driving back
    into each other, so the state matrix ``A`` is block triangular: the magnet's negative
    stiffness gives ±√A[1,0] (the unstable pole and its stable mirror), each lag its own
    diagonal entry (``lags`` names them in state order)."""
    A = np.asarray(A, dtype=float)
    a = float(np.sqrt(A[1, 0]))
    named = [(complex(a), f"{body} position (unstable magnet pole)"),
             (complex(-a), f"{body} position (stable mirror of the magnet pole)")]
    named += [(complex(A[2 + k, 2 + k]), name) for k, name in enumerate(lags[:A.shape[0] - 2])]
    return nearest_names(poles_s, named)


#: the lags of the radial bearing axis (paper 000 eq. 4 and 12), in ``RIG.continuous_model``'s state order
AXIS_LAGS = ("coil current (amplifier lag T_a)", "position sensor lag T_mx")
#: the maglev ball's coil (paper 004 eq. 2.8: R/L), in ``TABLE_3_1.linear_model``'s state order
MAGLEV_LAGS = ("coil current (R/L)",)


def axis_plant_names(poles_s) -> list[str | None]:
    """Names of the radial axis's open-loop plant poles (``RIG.continuous_model``): its only
    state beyond x, v and i is the sensor lag x_d, so the one real pole left is that lag's."""
    names = magnet_plant_names(poles_s, RIG.continuous_model(0.0).A, "rotor", AXIS_LAGS[:1])
    return [AXIS_LAGS[1] if name is None and abs(p.imag) == 0 and p.real < 0 else name
            for p, name in zip(np.asarray(poles_s, dtype=complex), names)]
