"""The controls of the radial bearing axis that several exercises share (paper 000, §II-IV and Appendix).

kalman_noise, ekf_parameters, ekf_disturbance and lqg_vs_pid run the same axis of the
same rig: its noise, its plant, the paper's PID and the run controls are defined here
once, with their defaults, so that the four exercises agree on them and no exercise
takes its controls from another.  A change here changes every exercise that lists the
control; an exercise that needs another default or group says so with
``dataclasses.replace``.
"""

from __future__ import annotations

import numpy as np

from lab_modules.parameters import Parameter
from lab_modules.plants.radial_bearing import DEFAULT_SENSOR_LAG_S, RIG

#: eq. 16: R = diag(7.1e-4 V^2, 1.4e-1 V^2) -> sensor noise in physical units
PAPER_SENSOR_NOISE_UM = np.sqrt(7.1e-4) / RIG.position_sensor_gain_v_per_m * 1e6      # 1.33 µm
PAPER_CURRENT_NOISE_A = np.sqrt(1.4e-1) / RIG.current_sensor_gain_v_per_a             # 1.87 A
#: The plant's unmodelled force disturbance (per sample).  The paper does not
#: give one; 0.5 N is small against the sensor noise, as the paper's Fig. 3
#: implies (the filter removes most of the motion, so noise dominated it).
DISTURBANCE_FORCE_N = 0.5
#: The amplifier's current noise per sample [A] (not in the paper).
AMPLIFIER_NOISE_A = 1e-3

P = Parameter

# -- the plant's noise -----------------------------------------------------------------------
PLANT_NOISE = (
    P("sensor_noise_um", "Position sensor noise σ", "µm", round(PAPER_SENSOR_NOISE_UM, 4), 0.0, 10.0,
      "Standard deviation of the position sensor's white noise (paper eq. 16: 1.33 µm).",
      step=0.01, group="Noise"),
    P("current_noise_a", "Current sensor noise σ", "A", round(PAPER_CURRENT_NOISE_A, 4), 0.0, 5.0,
      "Standard deviation of the current sensor's white noise (paper eq. 16: 1.87 A).",
      step=0.01, group="Noise"),
    P("disturbance_force_n", "Unmodelled force σ", "N", DISTURBANCE_FORCE_N, 0.0, 50.0,
      "Random force on the rotor, per 50 µs sample (the plant's process noise).",
      step=0.1, group="Noise"),
)

# -- the linear Kalman filter's measurement variances (eq. 16) -------------------------------------
FILTER_R_POSITION = P("filter_r_position", "Filter R_x", "V²", 7.1e-4, 1e-7, 1e-1,
                      "Filter's position-measurement variance (eq. 16: 7.1e-4 V²).", log=True,
                      group="Kalman filter")
FILTER_R_CURRENT = P("filter_r_current", "Filter R_i", "V²", 1.4e-1, 1e-4, 10.0,
                     "Filter's current-measurement variance (eq. 16: 0.14 V²).", log=True,
                     group="Kalman filter")

# -- the extended Kalman filters' noise (§III, eq. 16-17) ------------------------------------------
EKF_VARIANCES = (
    P("filter_q_velocity", "Filter q_22 (v)", "m²/s²", 2.6e-10, 1e-16, 1e-6,
      "Process noise of v per sample (eq. 17: 2.6e-10 m²/s²).", log=True, group="Extended Kalman filter"),
    P("filter_q_current", "Filter q_33 (i)", "A²", 1e-3, 1e-8, 1.0,
      "Process noise of i per sample (eq. 17: 0.43 A² on the rig; lab default 1e-3 A², see worksheet).",
      log=True, group="Extended Kalman filter"),
    P("filter_r_position", "Filter R_x", "V²", 7.1e-4, 1e-7, 1e-1,
      "Position-measurement variance (eq. 16: 7.1e-4 V²).", log=True, group="Extended Kalman filter"),
    P("filter_r_current", "Filter R_i", "V²", 1.4e-1, 1e-4, 10.0,
      "Current-measurement variance (eq. 16: 0.14 V²).", log=True, group="Extended Kalman filter"),
)

# -- the paper's PID (§IV: K = 0.65, T_I = 50 ms, T_D = 3 ms) ------------------------------------
PAPER_PID = (
    P("pid_gain", "PID gain K", "V/V", 0.65, 0.05, 5.0,
      "Proportional gain on the sensor voltage (paper §IV: 0.65).", step=0.01, group="Controller"),
    P("integral_time_ms", "Integral time T_I", "ms", 50.0, 1.0, 1000.0,
      "PID integral time (paper §IV: 50 ms).", step=1.0, group="Controller"),
    P("derivative_time_ms", "Derivative time T_D", "ms", 3.0, 0.1, 20.0,
      "PID derivative time (paper §IV: 3 ms).", step=0.1, group="Controller"),
    P("derivative_filter_us", "Derivative filter τ", "µs", 300.0, 50.0, 3000.0,
      "Time constant of the derivative's first-order filter (not in the paper: T_D/10).",
      step=10.0, group="Controller"),
)

# -- the plant -----------------------------------------------------------------------------------
FORCE_LAW = P("force_law", "Plant force law", "", "nonlinear", choices=("nonlinear", "linear"),
              description="True plant: eq. 10 (nonlinear) or its linearisation eq. 3.", group="Plant")
SENSOR_LAG = P("sensor_lag_us", "Sensor lag T_mx", "µs", DEFAULT_SENSOR_LAG_S * 1e6, 0.0, 1000.0,
               "Position sensor's demodulator lag, eq. 12 (not in the paper; 0 = ideal sensor).",
               step=10.0, group="Plant")

# -- the run -------------------------------------------------------------------------------------
SEED = P("seed", "Random seed", "", 0, 0, 2**31 - 1, "Seed of this lab's noise.", integer=True,
         step=1, group="Run")
TIME_SCALE = P("time_scale", "Time scale", "×", 0.01, 0.001, 1.0,
               "Simulated seconds per wall-clock second in the browser (1 = real time).",
               log=True, group="Run")
