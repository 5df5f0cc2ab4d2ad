"""Controls and builders that the flexible-rotor exercises (``sensor_placement``,
``rotor_at_speed``) share: the sensors by position (paper 000 §I: the integrated
capacitive sensor in the bearing's pole gaps, an eddy-current sensor on its own
track), their noise (eq. 16), the paper's PID and the Kalman filter on the paper's
rigid one-axis model (eq. 2-4, 12).  The values the paper leaves out are explained
in ``sensor_placement``'s docstring and worksheet."""

from __future__ import annotations

from functools import lru_cache

import control
import numpy as np

from lab_modules import analysis
from lab_modules.exercises._common import pid_from_values
from lab_modules.parameters import Parameter
from lab_modules.plants.flexible_rotor import RotorGeometry
from lab_modules.plants.radial_bearing import RIG

T = RIG.sample_time_s
K_MX, K_MI = RIG.position_sensor_gain_v_per_m, RIG.current_sensor_gain_v_per_a
GEOMETRY = RotorGeometry()
#: eq. 16: R_x = 7.1e-4 V^2 at K_mx = 20 mV/µm -> 1.33 µm
CAPACITIVE_NOISE_UM = float(np.sqrt(7.1e-4) / K_MX * 1e6)
EDDY_CURRENT_NOISE_UM = 0.27
CURRENT_NOISE_A = float(np.sqrt(1.4e-1) / K_MI)          # eq. 16: 1.87 A
EXTERNAL_OFFSET_MM = 60.0
INTEGRATED_HALF_WIDTH_MM = GEOMETRY.stack_length_m / 2 * 1e3
OFFSET_RANGE_MM = (-100.0, 100.0)
DISTURBANCE_FORCE_N = 0.5                                # unmodelled force per sample, as kalman_noise
AMPLIFIER_NOISE_A = 1e-3

P = Parameter
CAPACITIVE_NOISE = P("capacitive_noise_um", "Integrated sensor noise σ", "µm", round(CAPACITIVE_NOISE_UM, 4),
                     0.0, 10.0, "Noise of the capacitive sensor in the pole gaps (paper eq. 16: 1.33 µm).",
                     step=0.01, group="Sensor")
EDDY_CURRENT_NOISE = P("eddy_current_noise_um", "External sensor noise σ", "µm", EDDY_CURRENT_NOISE_UM, 0.0, 10.0,
                       "Noise of the eddy-current sensor (not in the paper: 0.27 µm, see worksheet).", step=0.01,
                       group="Sensor")
SENSOR_LAG = P("sensor_lag_us", "Sensor lag T_mx", "µs", 50.0, 0.0, 500.0,
               "First-order lag of either sensor, eq. 12 (not in the paper: 50 µs, see worksheet).", step=5.0,
               group="Sensor")
CONTROLLER = (
    P("gain_factor", "Common gain factor", "×", 1.0, 0.05, 4.0,
      "Multiplies the PID gain K (paper: +75 % with the integrated sensor).", step=0.01, group="Controller"),
    P("pid_gain", "PID gain K", "V/V", 0.65, 0.05, 5.0, "Paper §IV: 0.65.", step=0.01, group="Controller"),
    P("integral_time_ms", "Integral time T_I", "ms", 50.0, 1.0, 1000.0, "Paper §IV: 50 ms.", step=1.0,
      group="Controller"),
    P("derivative_time_ms", "Derivative time T_D", "ms", 3.0, 0.1, 20.0, "Paper §IV: 3 ms.", step=0.1,
      group="Controller"),
    P("derivative_filter_us", "Derivative filter τ", "µs", 300.0, 50.0, 3000.0,
      "Derivative's first-order filter (not in the paper: T_D/10).", step=10.0, group="Controller"),
    P("feedback", "Feedback source", "", "measured", choices=("measured", "estimated"),
      description="Position the PID acts on: the sensor's reading or the Kalman filter's estimate "
                  "(filter model: the paper's rigid rotor, eq. 3-4).", group="Controller"),
)
MODAL_DAMPING = P("modal_damping_percent", "Bending-mode damping ζ", "%", 100 * GEOMETRY.modal_damping, 0.0, 5.0,
                  "Structural damping of the bending modes (not in the paper: 0.5 %).", step=0.1, group="Rotor")
DISTURBANCE_FORCE = P("disturbance_force_n", "Unmodelled force σ", "N", DISTURBANCE_FORCE_N, 0.0, 50.0,
                      "Random force at the bearing, per 50 µs sample (process noise).", step=0.1,
                      group="Excitation")


def integrated(sensor_offset_mm: float) -> bool:
    """Is the sensor at this position the capacitive one in the bearing's pole gaps?"""
    return abs(sensor_offset_mm) <= INTEGRATED_HALF_WIDTH_MM


def sensor_noise_m(values: dict, sensor_offset_mm: float | None = None) -> float:
    offset = values["sensor_offset_mm"] if sensor_offset_mm is None else sensor_offset_mm
    sensor = CAPACITIVE_NOISE if integrated(offset) else EDDY_CURRENT_NOISE
    return sensor.si(values)


@lru_cache(maxsize=64)
def rigid_filter(sensor_lag_s: float, noise_m: float, force_n: float):
    """Filter model (the paper's rigid axis, eq. 3-4, 12) and its steady-state gain (eq. 2):
    (model, K, Q, R)."""
    model = RIG.discrete_model(sensor_lag_s)
    n = model.nstates
    Q = np.zeros((n, n))
    Q[1, 1] = max(force_n * T / RIG.equivalent_mass_kg, 1e-9) ** 2
    Q[2, 2] = AMPLIFIER_NOISE_A**2
    R = np.diag([max(K_MX * noise_m, 1e-6) ** 2, (K_MI * CURRENT_NOISE_A) ** 2])
    gain, _ = analysis.steady_state_kalman(model, Q, R)
    return model, gain, Q, R


def filter_for(values: dict, sensor_offset_mm: float | None = None):
    """``rigid_filter`` for the sensor at this position (default: the values')."""
    return rigid_filter(SENSOR_LAG.si(values), sensor_noise_m(values, sensor_offset_mm),
                        values["disturbance_force_n"])


def scaled_pid(values: dict, gain_factor: float | None = None) -> control.StateSpace:
    """The PID of the controller sliders with its gain K times the gain factor (default: the values')."""
    return pid_from_values(values) * (values["gain_factor"] if gain_factor is None else gain_factor)
