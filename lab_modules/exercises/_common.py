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
