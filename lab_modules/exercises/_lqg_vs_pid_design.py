"""The two loops of ``lqg_vs_pid`` from its controls, and their poles (paper 000, §IV, eq. 19-22, Fig. 7).

The LQG: a discrete LQR with the superimposed integral controller acting on the Kalman
filter's estimate (``controllers.lqr``), with eq. 22's printed gains, the gains of the
weights set on the controls, or the redesign preset.  The PID: the paper's root-locus PID
on the estimated or the measured position, optionally as an I-PD (reference through the
integral only).  Both share the rig, the noise, the filter and the excitation.
"""

from __future__ import annotations

import numpy as np

from lab_modules import analysis
from lab_modules.controllers.lqr import (
    PAPER_LQG,
    PAPER_LQR_WEIGHTS,
    StateFeedback,
    integral_augmented_model,
    lqr,
)
from lab_modules.controllers.pid import setpoint_filter
from lab_modules.exercises._common import pid_from_values
from lab_modules.exercises._radial_axis_controls import AMPLIFIER_NOISE_A, PAPER_PID, PLANT_NOISE, SENSOR_LAG
from lab_modules.loops.radial_axis_experiment import AxisSetup
from lab_modules.loops.radial_axis_step_tests import loop_figures
from lab_modules.parameters import Parameter, in_si
from lab_modules.plants.radial_bearing import RIG

T = RIG.sample_time_s
LOOPS = ("LQG", "PID")
COLORS = {"LQG": "#d62728", "PID": "#1f77b4", "reference": "#7f7f7f"}

#: Choices of the LQG gains: eq. 22 as printed, dlqr of the sliders, the redesign preset.
PAPER_GAINS, DESIGNED, REDESIGN = "paper eq. 22", "LQR from Q_J, R_J", "redesign preset"
#: The redesign preset (issue's "an LQG that beats the PID"): the paper's weights
#: (``PAPER_LQR_WEIGHTS``) times these factors on (x, v, i, ∫e), R_J = 1 V⁻².
#: Stiffer position and velocity weights make the state feedback stiffer; the
#: integral weight ×10 keeps the regulator's dominant poles 5× slower than the
#: filter's, and the reference still enters through the integrator only.
REDESIGN_FACTORS = (316.0, 316.0, 1.0, 10.0)
REDESIGN_WEIGHTS = tuple(f * w for f, w in zip(REDESIGN_FACTORS, PAPER_LQR_WEIGHTS))

P = Parameter
#: The steps of Figs. 8-9 and the scope's square wave, defined beside the set-up that reads them.
EXCITATION = (
    P("reference_step_um", "Reference step Δx", "µm", 50.0, 1.0, 200.0,
      "Reference position step (Fig. 8: 50 µm).", step=1.0, group="Excitation"),
    P("disturbance_step_n", "Disturbance step Δf_z", "N", 400.0, 10.0, 1000.0,
      "Step of the disturbance force f_z (Fig. 9: 400 N).", step=10.0, group="Excitation"),
    P("scope_excitation", "Scope excitation", "", "reference step",
      choices=("reference step", "disturbance step"),
      description="Which step the live scope repeats as a square wave.", group="Excitation"),
    P("step_period_ms", "Step period", "ms", 200.0, 20.0, 1000.0,
      "Period of the scope's square wave.", step=10.0, group="Excitation"),
)
#: The controls whose SI values the loops' set-up reads.
SET_UP_CONTROLS = (*PAPER_PID, *PLANT_NOISE, SENSOR_LAG, *EXCITATION)


def regulator(values: dict) -> StateFeedback:
    """The LQG's state feedback: eq. 22 as printed, eq. 19-21 for the set
    weights, or eq. 19-21 for the redesign preset's weights."""
    if values["lqg_gains"] == PAPER_GAINS:
        return PAPER_LQG
    if values["lqg_gains"] == REDESIGN:
        return lqr(REDESIGN_WEIGHTS, 1.0)
    return lqr_from_weights(values)


def lqr_from_weights(values: dict) -> StateFeedback:
    """Eq. 19-21 for the weights Q_J, R_J set on the controls."""
    weights = tuple(values[name] for name in ("q_position", "q_velocity", "q_current", "q_integral"))
    return lqr(weights, values["r_control"])


def pid_reference_filter(values: dict, derivative_time_s: float | None = None):
    """The I-PD's reference filter for the PID sliders (None for the plain PID)."""
    if values["pid_structure"] != "I-PD":
        return None
    si = in_si(SET_UP_CONTROLS, values)
    if derivative_time_s is None:
        derivative_time_s = si["derivative_time_ms"]
    return setpoint_filter(si["integral_time_ms"], derivative_time_s,
                           derivative_time_s * derivative_filter_ratio(values), T)


def derivative_filter_ratio(values: dict) -> float:
    """tau / T_D of the PID sliders (the fronts keep it while they sweep T_D)."""
    return values["derivative_filter_us"] * 1e-3 / values["derivative_time_ms"]


def common_setup(values: dict) -> AxisSetup:
    """Rig, noise, filter and excitation that both loops share (no controller yet)."""
    scope_reference = values["scope_excitation"] == "reference step"
    si = in_si(SET_UP_CONTROLS, values)
    return AxisSetup(
        controller=None,
        nonlinear=values["force_law"] == "nonlinear",
        sensor_lag_s=si["sensor_lag_us"],
        sensor_noise_m=si["sensor_noise_um"],
        current_noise_a=values["current_noise_a"],
        process_force_n=values["disturbance_force_n"],
        process_current_a=AMPLIFIER_NOISE_A,
        filter_q_velocity=values["filter_q_velocity"],
        filter_q_current=values["filter_q_current"],
        filter_r_position=values["filter_r_position"],
        filter_r_current=values["filter_r_current"],
        reference_step_m=si["reference_step_um"] if scope_reference else 0.0,
        disturbance_step_n=0.0 if scope_reference else values["disturbance_step_n"],
        step_period_s=si["step_period_ms"],
    )


def lqg_setup(common: AxisSetup, lqg: StateFeedback, values: dict) -> AxisSetup:
    """The shared set-up with the LQG: its integral controller and its state gain on the estimate."""
    return common.with_changes(controller=lqg.integrator(), state_gain=lqg.state_gain,
                               use_estimate=values["integrator_input"] == "estimated")


def setups(values: dict) -> dict[str, AxisSetup]:
    """The LQG and the PID loop: same rig, noise, filter and excitation."""
    common = common_setup(values)
    return {
        "LQG": lqg_setup(common, regulator(values), values),
        "PID": common.with_changes(controller=pid_from_values(values),
                                   use_estimate=values["pid_feedback"] == "estimated",
                                   reference_filter=pid_reference_filter(values)),
    }


# -- poles (Fig. 7) --------------------------------------------------------------------

def pole_sets(loops: dict[str, AxisSetup], lqg: StateFeedback) -> dict[str, np.ndarray]:
    """Continuous-equivalent poles [rad/s], drawn in this order (later on top):
    the open-loop plant, the PID loop, the regulator A_aug - B_aug K on the
    nominal model (Fig. 7's "LQG controlled system") and the steady-state
    filter's error poles eig(A - A K_f C).  With the integrator on the estimate
    the LQG loop's poles are exactly the last two sets (separation principle)."""
    axis = loops["LQG"]
    return {
        "open-loop plant": np.linalg.eigvals(np.asarray(RIG.continuous_model(axis.sensor_lag_s).A)),
        "PID loop with filter": analysis.z_to_s(analysis.loop_poles(loops["PID"].loop()), T),
        **regulator_and_filter_poles(axis, lqg),
    }


def regulator_and_filter_poles(axis: AxisSetup, lqg: StateFeedback) -> dict[str, np.ndarray]:
    """Fig. 7: the regulator's poles A_aug - B_aug K and the filter's error poles [rad/s]."""
    A_aug, B_aug = integral_augmented_model(axis.rig)
    gain = np.array([*lqg.state_gain, -lqg.integral_gain_v_per_m_s])
    K_f, _ = axis.steady_state_filter
    A, C = np.asarray(axis.model.A), np.asarray(axis.model.C)
    return {"LQG regulator": analysis.z_to_s(np.linalg.eigvals(A_aug - B_aug @ gain[None]), T),
            "Kalman filter error": analysis.z_to_s(np.linalg.eigvals(A - A @ K_f @ C), T)}


def lqg_loop_poles(loops: dict[str, AxisSetup]) -> np.ndarray:
    """Poles [rad/s] of the whole LQG loop (plant, filter, regulator)."""
    return analysis.z_to_s(analysis.loop_poles(loops["LQG"].loop()), T)


def dominant_real_part(poles_s: np.ndarray) -> float:
    """Real part [rad/s] of the dominant (slowest) pole."""
    return float(np.max(np.real(poles_s)))


def dominant_pole_ratio(poles: dict[str, np.ndarray]) -> float:
    """Fig. 7's statement as a number: Re of the filter's dominant pole over Re of the regulator's."""
    return dominant_real_part(poles["Kalman filter error"]) / dominant_real_part(poles["LQG regulator"])


def redesign_figures(values: dict) -> dict[str, float]:
    """The redesign preset's LQG at the current filter, noise and integrator
    settings: ``loop_figures`` and the filter/regulator dominant pole ratio."""
    preset = lqr(REDESIGN_WEIGHTS, 1.0)
    axis = lqg_setup(common_setup(values), preset, values)
    return {**loop_figures(axis), "pole_ratio": dominant_pole_ratio(regulator_and_filter_poles(axis, preset))}
