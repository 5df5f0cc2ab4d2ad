"""Exercise ``lqg_vs_pid``: the LQG regulator against the optimal PID.

Paper 000 (Schuhmann, Hofmann, Werner), §IV, eq. 19-22, Figs. 7-9 and
Appendix.  With the Kalman filter every state (x, v, i) is available, so a
discrete LQR (eq. 19-21) plus the paper's superimposed integral controller
can act on the estimate: u = i_ref = -K x_hat + K_I xi, xi the integral of
the position error (``controllers.lqr.StateFeedback`` states the units the lab
reads into eq. 22).  It is compared, on the same noise, with the paper's
root-locus PID (K = 0.65, T_I = 50 ms, T_D = 3 ms) on a 50 µm reference step
(Fig. 8) and a 400 N disturbance step (Fig. 9); the pole map sets the
regulator's poles against the filter's (Fig. 7).

The estimator is the fourth-order linear filter of Fig. 7, states
(x, v, i, x_d) with the sensor lag of eq. 12, and eq. 16-17's variances as
defaults (q_vv = 2.6e-10 m²/s², q_ii = 0.43 A², R = diag(7.1e-4, 0.14) V²).
Both loops use it: the PID on the estimated position (as in §II), so the
comparison is between control laws, not between estimators.

Step figures (overshoot, settling time, peak and RMS control current, the
dynamic stiffness s_dyn = Δf_z / Δx_max of §IV) come from noise-free runs of
the compiled loop on the chosen plant (nonlinear eq. 10 by default): a step
at t = 0 after 5 ms at rest, observed for 150 ms.  Settling: the last time
the rotor is outside ±2 % of the reference step.  A loop that loses the
rotor reports the largest disturbance step it holds instead.

Stiffness in two definitions, on the linear loop with the filter in use:
the step stiffness (Fig. 9's definition) and the minimum over frequency of
|F/X(jω)|.  With eq. 22 read in SI units the LQG is the softer loop by both
(a documented deviation, see ``CLAIMS``).  What an LQG buys here the
trade-off fronts show: sweeps of both families (LQG weights, PID gain and
T_D) plotted as stiffness against noise current and against the current a
reference step costs.  The I-PD option (the PID with its reference through
the integral only) separates the LQG's structural advantage on set-point
changes from its optimality; the redesign preset is one LQG on the front
that is as stiff as the printed PID.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from lab_modules import analysis
from lab_modules.claims import Claim
from lab_modules.controllers.lqr import (
    PAPER_LQG,
    PAPER_LQR_WEIGHTS,
    StateFeedback,
    integral_augmented_model,
    lqr,
)
from lab_modules.controllers.pid import pid, setpoint_filter
from lab_modules.exercises import Analysis, Chart, Exercise, Plot, Series, kalman_noise
from lab_modules.exercises._common import (
    AXIS_STATES,
    INTEGRAL_STATE,
    axis_mode_matrices,
    axis_plant_names,
    pid_from_values,
)
from lab_modules.loops.radial_axis_experiment import AxisSetup, AxisSimulation
from lab_modules.loops.radial_axis_loop import OK, TRACE_COLUMNS
from lab_modules.parameters import Parameter
from lab_modules.plants.radial_bearing import RIG
from lab_modules.scenes.bearing import ESTIMATE_RED, TRUE_BLUE, BearingScene, Ghost

T = RIG.sample_time_s
LOOPS = ("LQG", "PID")
COLORS = {"LQG": "#d62728", "PID": "#1f77b4", "reference": "#7f7f7f"}
#: Step test (Figs. 8-9): rest before the step, observation after it, settling band.
BEFORE_STEP_S, AFTER_STEP_S, SETTLING_BAND = 5e-3, 0.15, 0.02
#: Linear step responses run longer: with a weak integral the deflection peaks late.
LINEAR_WINDOW_S = 0.3
#: Largest disturbance step: searched up to the slider's maximum, to this resolution.
LARGEST_STEP_TRIED_N, LARGEST_STEP_RESOLUTION_N = 1000.0, 5.0
PLOT_POINTS = 500

#: Choices of the LQG gains: eq. 22 as printed, dlqr of the sliders, the redesign preset.
PAPER_GAINS, DESIGNED, REDESIGN = "paper eq. 22", "LQR from Q_J, R_J", "redesign preset"
#: The redesign preset (issue's "an LQG that beats the PID"): the paper's weights
#: (``PAPER_LQR_WEIGHTS``) times these factors on (x, v, i, ∫e), R_J = 1 V⁻².
#: Stiffer position and velocity weights make the state feedback stiffer; the
#: integral weight ×10 keeps the regulator's dominant poles 5× slower than the
#: filter's, and the reference still enters through the integrator only.
REDESIGN_FACTORS = (316.0, 316.0, 1.0, 10.0)
REDESIGN_WEIGHTS = tuple(f * w for f, w in zip(REDESIGN_FACTORS, PAPER_LQR_WEIGHTS))

_kalman_noise = {p.name: p for p in kalman_noise.PARAMETERS}
P = Parameter
PARAMETERS = (
    P("lqg_gains", "LQG gains", "", PAPER_GAINS, choices=(PAPER_GAINS, DESIGNED, REDESIGN),
      description="The paper's K = (9979, 29.686, 0.073), K_I = 1.03e6; dlqr with the weights below; "
                  "or the redesign preset: dlqr with the paper's weights on x and v ×316 and on ∫e ×10.",
      group="LQG regulator"),
    P("q_position", "Q_J weight on x", "1/m²", PAPER_LQR_WEIGHTS[0], 1e3, 1e10,
      "Eq. 19 weight on the position (default: reproduces eq. 22 with R_J = 1).", log=True,
      group="LQG regulator"),
    P("q_velocity", "Q_J weight on v", "s²/m²", PAPER_LQR_WEIGHTS[1], 1e-2, 1e5,
      "Eq. 19 weight on the velocity.", log=True, group="LQG regulator"),
    P("q_current", "Q_J weight on i", "1/A²", PAPER_LQR_WEIGHTS[2], 1e-6, 1e2,
      "Eq. 19 weight on the control current.", log=True, group="LQG regulator"),
    P("q_integral", "Q_J weight on ∫e", "1/(m·s)²", PAPER_LQR_WEIGHTS[3], 1e8, 1e16,
      "Eq. 19 weight on the integral of the position error (the integral controller).", log=True,
      group="LQG regulator"),
    P("r_control", "R_J weight on i_ref", "1/V²", 1.0, 1e-3, 1e3,
      "Eq. 19 weight on the amplifier input u = i_ref.", log=True, group="LQG regulator"),
    P("integrator_input", "Integrator input", "", "estimated", choices=("estimated", "measured"),
      description="Position error the integral controller sums: of the filter's estimate or of the sensor.",
      group="LQG regulator"),
    *(replace(_kalman_noise[name], group="PID") for name in
      ("pid_gain", "integral_time_ms", "derivative_time_ms", "derivative_filter_us")),
    P("pid_structure", "PID structure", "", "PID", choices=("PID", "I-PD"),
      description="PID: P, I and D act on the error r − x (the paper's). I-PD (set-point weights b = c = 0): "
                  "the reference enters through the integral only, as in the LQG.",
      group="PID"),
    P("pid_feedback", "PID feedback", "", "estimated", choices=("estimated", "measured"),
      description="Position the PID acts on: the filter's estimate (as the LQG) or the sensor's.",
      group="PID"),
    P("filter_q_velocity", "Filter Q_vv", "m²/s²", 2.6e-10, 1e-16, 1e-6,
      "Filter's process-noise variance on v per sample (eq. 17: 2.6e-10 m²/s²).", log=True,
      group="Kalman filter"),
    P("filter_q_current", "Filter Q_ii", "A²", 0.43, 1e-10, 10.0,
      "Filter's process-noise variance on i per sample (eq. 17: 0.43 A²).", log=True, group="Kalman filter"),
    *(_kalman_noise[name] for name in ("filter_r_position", "filter_r_current", "sensor_noise_um",
                                       "current_noise_a", "disturbance_force_n", "force_law", "sensor_lag_us")),
    P("reference_step_um", "Reference step Δx", "µm", 50.0, 1.0, 200.0,
      "Reference position step (Fig. 8: 50 µm).", step=1.0, group="Excitation"),
    P("disturbance_step_n", "Disturbance step Δf_z", "N", 400.0, 10.0, 1000.0,
      "Step of the disturbance force f_z (Fig. 9: 400 N).", step=10.0, group="Excitation"),
    P("scope_excitation", "Scope excitation", "", "reference step",
      choices=("reference step", "disturbance step"),
      description="Which step the live scope repeats as a square wave.", group="Excitation"),
    P("step_period_ms", "Step period", "ms", 200.0, 20.0, 1000.0,
      "Period of the scope's square wave.", step=10.0, group="Excitation"),
    _kalman_noise["seed"],
    replace(_kalman_noise["time_scale"], default=0.02),
)


def regulator(values: dict) -> StateFeedback:
    """The LQG's state feedback: eq. 22 as printed, eq. 19-21 for the set
    weights, or eq. 19-21 for the redesign preset's weights."""
    if values["lqg_gains"] == PAPER_GAINS:
        return PAPER_LQG
    if values["lqg_gains"] == REDESIGN:
        return lqr(REDESIGN_WEIGHTS, 1.0)
    return lqr_from_weights(values)


def lqr_from_weights(values: dict) -> StateFeedback:
    weights = tuple(values[name] for name in ("q_position", "q_velocity", "q_current", "q_integral"))
    return lqr(weights, values["r_control"])


def pid_reference_filter(values: dict, derivative_time_s: float | None = None):
    """The I-PD's reference filter for the PID sliders (None for the plain PID)."""
    if values["pid_structure"] != "I-PD":
        return None
    if derivative_time_s is None:
        derivative_time_s = values["derivative_time_ms"] * 1e-3
    return setpoint_filter(values["integral_time_ms"] * 1e-3, derivative_time_s,
                           derivative_time_s * derivative_filter_ratio(values), T)


def derivative_filter_ratio(values: dict) -> float:
    """tau / T_D of the PID sliders (the fronts keep it while they sweep T_D)."""
    return values["derivative_filter_us"] * 1e-3 / values["derivative_time_ms"]


def common_setup(values: dict) -> AxisSetup:
    """Rig, noise, filter and excitation that both loops share (no controller yet)."""
    scope_reference = values["scope_excitation"] == "reference step"
    return AxisSetup(
        controller=None,
        nonlinear=values["force_law"] == "nonlinear",
        sensor_lag_s=values["sensor_lag_us"] * 1e-6,
        sensor_noise_m=values["sensor_noise_um"] * 1e-6,
        current_noise_a=values["current_noise_a"],
        process_force_n=values["disturbance_force_n"],
        process_current_a=kalman_noise.AMPLIFIER_NOISE_A,
        filter_q_velocity=values["filter_q_velocity"],
        filter_q_current=values["filter_q_current"],
        filter_r_position=values["filter_r_position"],
        filter_r_current=values["filter_r_current"],
        reference_step_m=values["reference_step_um"] * 1e-6 if scope_reference else 0.0,
        disturbance_step_n=0.0 if scope_reference else values["disturbance_step_n"],
        step_period_s=values["step_period_ms"] * 1e-3,
    )


def lqg_setup(common: AxisSetup, lqg: StateFeedback, values: dict) -> AxisSetup:
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


# -- step tests (Figs. 8-9) ----------------------------------------------------------

def step_response(axis: AxisSetup, reference_m: float, force_n: float) -> tuple[np.ndarray, str]:
    """Noise-free response of one loop to a step at t = 0: rows (t [s], TRACE_COLUMNS)
    from -``BEFORE_STEP_S`` to ``AFTER_STEP_S``, and the stop message ('' if none)."""
    period = 2.0 * (BEFORE_STEP_S + AFTER_STEP_S)          # the square wave switches on at period / 2
    quiet = axis.with_changes(sensor_noise_m=0.0, current_noise_a=0.0, process_force_n=0.0,
                              process_current_a=0.0, reference_step_m=reference_m,
                              disturbance_step_n=force_n, step_period_s=period)
    sim = AxisSimulation(quiet)
    sim.step = round(AFTER_STEP_S / T)
    trace = sim.advance(round((BEFORE_STEP_S + AFTER_STEP_S) / T))
    trace[:, 0] -= 0.5 * period
    return trace, sim.status_message()


def column(trace: np.ndarray, name: str) -> np.ndarray:
    return trace[:, 1 + TRACE_COLUMNS.index(name)]


def reference_step_figures(trace: np.ndarray, step_m: float) -> dict[str, float]:
    """Overshoot [%], settling time [s] (±2 % band), peak and RMS coil current [A] after the step."""
    after = trace[trace[:, 0] >= 0.0]
    x, current = column(after, "x_true_m"), column(after, "current_a")
    outside = np.flatnonzero(np.abs(x - step_m) > SETTLING_BAND * abs(step_m))
    complete = len(after) >= round(AFTER_STEP_S / T)
    if not complete or outside.size and outside[-1] == len(x) - 1:
        settling = float("nan")
    else:
        settling = float(after[outside[-1] + 1, 0]) if outside.size else 0.0
    return {"overshoot_percent": 100.0 * (np.max(x / step_m) - 1.0) if complete else float("nan"),
            "settling_time_s": settling,
            "peak_current_a": float(np.max(np.abs(current))),
            "rms_current_a": float(np.sqrt(np.mean(current**2)))}


def _scaled(value, factor: float):
    """A readout value in display units, or the word that stands for it."""
    return value if isinstance(value, str) else value * factor


def disturbance_step_figures(trace: np.ndarray, force_n: float) -> dict[str, float]:
    """Largest deviation [m] from the (zero) reference, s_dyn = |Δf_z| / Δx_max [N/m],
    the offset [m] left at the end of the window and the peak coil current [A] after the step."""
    after = trace[trace[:, 0] >= 0.0]
    x = column(after, "x_true_m")
    complete = len(after) >= round(AFTER_STEP_S / T)
    deviation = float(np.max(np.abs(x))) if complete else float("nan")
    return {"max_deviation_m": deviation, "dynamic_stiffness_n_per_m": abs(force_n) / deviation,
            "final_offset_m": float(x[-1]) if complete else float("nan"),
            "peak_current_a": float(np.max(np.abs(column(after, "current_a"))))}


def step_tests(loops: dict[str, AxisSetup], values: dict) -> dict[str, dict]:
    """Both step tests for both loops: traces, figures and stop messages."""
    reference_m, force_n = values["reference_step_um"] * 1e-6, values["disturbance_step_n"]
    results = {}
    for name, axis in loops.items():
        reference_trace, reference_stop = step_response(axis, reference_m, 0.0)
        force_trace, force_stop = step_response(axis, 0.0, force_n)
        results[name] = {"reference": reference_trace, "disturbance": force_trace,
                         "stops": [m for m in (reference_stop, force_stop) if m],
                         **{f"reference_{k}": v for k, v in reference_step_figures(reference_trace,
                                                                                   reference_m).items()},
                         **{f"disturbance_{k}": v for k, v in disturbance_step_figures(force_trace,
                                                                                       force_n).items()}}
    return results


def largest_disturbance_step(axis: AxisSetup, upper_n: float = LARGEST_STEP_TRIED_N,
                             resolution_n: float = LARGEST_STEP_RESOLUTION_N) -> float:
    """Largest disturbance step [N] up to ``upper_n`` that the loop holds for the
    step test's 150 ms without touchdown (noise-free, chosen plant), by bisection
    to ``resolution_n``.  On the nonlinear plant the force law eq. 10 softens
    with the deflection, so a loop that is stable for small steps can still
    lose the rotor on a large one."""
    def holds(force_n: float) -> bool:
        return step_response(axis, 0.0, force_n)[1] == ""

    if holds(upper_n):
        return upper_n
    low, high = 0.0, upper_n
    while high - low > resolution_n:
        middle = 0.5 * (low + high)
        low, high = (middle, high) if holds(middle) else (low, middle)
    return low


# -- two stiffness definitions on the linear loop ---------------------------------------

def linear_figures(loop: analysis.Loop) -> dict[str, float]:
    """The loop's figures on the linear plant with the steady-state filter
    (python-control-style system of ``analysis.closed_loop``):

    * ``step_stiffness_n_per_m``: |Δf| / largest deflection after a force step
      (paper 000 §IV, Fig. 9's s_dyn, here over ``LINEAR_WINDOW_S``);
    * ``min_dynamic_stiffness_n_per_m`` and ``..._frequency_hz``: the smallest
      |F/X(jω)| over frequency (the ISO 14839 style figure: a sinusoidal force
      at the worst frequency);
    * ``overshoot_percent``, ``peak_current_a_per_m`` (peak coil current per
      metre of reference step: linear, so scale by the step), ``settling_time_s``
      (±2 %) of a reference step;
    * ``min_damping``: the smallest damping ratio ζ among the loop's poles
      (1 for none complex; ≤ 0 unstable).

    Unstable loops return NaN figures (and their ``min_damping``)."""
    poles = analysis.z_to_s(analysis.loop_poles(loop), T)
    damping = float(np.min(-poles.real / np.maximum(np.abs(poles), 1e-300)))
    nan = float("nan")
    if not np.all(poles.real < 0):
        return {"step_stiffness_n_per_m": nan, "min_dynamic_stiffness_n_per_m": nan,
                "min_dynamic_stiffness_frequency_hz": nan, "overshoot_percent": nan,
                "peak_current_a_per_m": nan, "settling_time_s": nan, "min_damping": damping}
    n = round(LINEAR_WINDOW_S / T)
    x_index, i_index = analysis.LOOP_OUTPUTS.index("x_m"), analysis.LOOP_OUTPUTS.index("current_a")
    force = analysis.step_response(loop, "disturbance_n", n)[:, x_index]
    reference = analysis.step_response(loop, "reference_m", n)
    x = reference[:, x_index]
    outside = np.flatnonzero(np.abs(x - 1.0) > SETTLING_BAND)
    compliance, frequency = analysis.peak_gain(loop, "disturbance_n", "x_m")
    return {"step_stiffness_n_per_m": 1.0 / float(np.max(np.abs(force))),
            "min_dynamic_stiffness_n_per_m": 1.0 / compliance,
            "min_dynamic_stiffness_frequency_hz": frequency,
            "overshoot_percent": 100.0 * (float(np.max(x)) - 1.0),
            "peak_current_a_per_m": float(np.max(np.abs(reference[:, i_index]))),
            "settling_time_s": (outside[-1] + 1) * T if outside.size else 0.0,
            "min_damping": damping}


def loop_figures(axis: AxisSetup) -> dict[str, float]:
    """``linear_figures`` of one set-up plus its noise-driven RMS coil current [A]
    and rotor displacement [m] (Lyapunov, ``analysis.noise_rms``)."""
    loop = axis.loop()
    figures = linear_figures(loop)
    rms = analysis.noise_rms(loop, axis.noise_variances)
    return {**figures, "noise_rms_current_a": float(rms["current_a"]), "noise_rms_x_m": float(rms["x_m"])}


def redesign_figures(values: dict) -> dict[str, float]:
    """The redesign preset's LQG at the current filter, noise and integrator
    settings: ``loop_figures`` and the filter/regulator dominant pole ratio."""
    preset = lqr(REDESIGN_WEIGHTS, 1.0)
    axis = lqg_setup(common_setup(values), preset, values)
    return {**loop_figures(axis), "pole_ratio": dominant_pole_ratio(regulator_and_filter_poles(axis, preset))}


# -- trade-off fronts (Analysis tab) -------------------------------------------------

#: LQG family: the paper's weights with q_x and q_v scaled together by one factor
#: and q_ξ by another, each over four decades (q_i, R_J as in the paper).
FRONT_LQG_FACTORS = np.geomspace(0.1, 1000.0, 9)
#: PID family: the gain K times these factors, at each derivative time T_D
#: (τ / T_D and T_I from the sliders).
FRONT_PID_GAIN_FACTORS = np.geomspace(0.25, 4.0, 13)
FRONT_PID_DERIVATIVE_TIMES_S = (0.5e-3, 1e-3, 1.5e-3, 2e-3, 3e-3, 4e-3, 6e-3)
#: A design counts on a front only if every closed-loop pole is damped at least this
#: much (lab choice): lighter damped loops ring for many periods; their step stiffness
#: looks good while their minimum dynamic stiffness collapses.  They are drawn grey.
FRONT_MIN_DAMPING = 0.15
#: The step-current front is read at this stiffness [N/m].
FRONT_STIFFNESS_TARGET_N_PER_M = 10e6


@dataclass(frozen=True)
class Designs:
    """One family of designs on the fronts: arrays of equal length."""

    step_stiffness_n_per_m: np.ndarray
    min_dynamic_stiffness_n_per_m: np.ndarray
    noise_rms_current_a: np.ndarray
    peak_current_a_per_m: np.ndarray            # reference step; for the PID family: the PID's
    peak_current_ipd_a_per_m: np.ndarray        # PID family only: the same loop as an I-PD
    min_damping: np.ndarray

    @property
    def admissible(self) -> np.ndarray:
        return self.min_damping >= FRONT_MIN_DAMPING


def _designs(rows: list[dict]) -> Designs:
    def column(name):
        return np.array([row.get(name, np.nan) for row in rows], dtype=float)
    return Designs(column("step_stiffness_n_per_m"), column("min_dynamic_stiffness_n_per_m"),
                   column("noise_rms_current_a"), column("peak_current_a_per_m"),
                   column("peak_current_ipd_a_per_m"), column("min_damping"))


#: The settings each family's front depends on (the rest move only the design markers).
_SHARED_FRONT_SETTINGS = ("filter_q_velocity", "filter_q_current", "filter_r_position", "filter_r_current",
                          "sensor_noise_um", "current_noise_a", "disturbance_force_n", "sensor_lag_us")
LQG_FRONT_SETTINGS = (*_SHARED_FRONT_SETTINGS, "integrator_input")
PID_FRONT_SETTINGS = (*_SHARED_FRONT_SETTINGS, "pid_feedback", "pid_gain", "integral_time_ms",
                      "derivative_time_ms", "derivative_filter_us")


def _linear_common(names: tuple[str, ...], key: tuple) -> tuple[dict, AxisSetup]:
    """Slider values (the front's settings, the rest neutral) and the shared set-up
    on the linear plant, its filter solved once for every design of the sweep."""
    values = dict(zip(names, key))
    values.update(force_law="linear", reference_step_um=0.0, disturbance_step_n=0.0,
                  scope_excitation="reference step", step_period_ms=200.0)
    common = common_setup(values)
    _ = common.steady_state_filter
    return values, common


@lru_cache(maxsize=16)
def _lqg_front(key: tuple) -> Designs:
    values, common = _linear_common(LQG_FRONT_SETTINGS, key)
    rows = []
    for factor_xv in FRONT_LQG_FACTORS:
        for factor_integral in FRONT_LQG_FACTORS:
            weights = np.array(PAPER_LQR_WEIGHTS) * (factor_xv, factor_xv, 1.0, factor_integral)
            rows.append(loop_figures(lqg_setup(common, lqr(tuple(weights), 1.0), values)))
    return _designs(rows)


@lru_cache(maxsize=16)
def _pid_front(key: tuple) -> Designs:
    values, common = _linear_common(PID_FRONT_SETTINGS, key)
    rows = []
    ratio = derivative_filter_ratio(values)
    for derivative_time_s in FRONT_PID_DERIVATIVE_TIMES_S:
        at_slider_gain = pid(values["pid_gain"], values["integral_time_ms"] * 1e-3,
                             derivative_time_s, ratio * derivative_time_s, T)
        prefilter = setpoint_filter(values["integral_time_ms"] * 1e-3, derivative_time_s,
                                    ratio * derivative_time_s, T)
        for factor in FRONT_PID_GAIN_FACTORS:
            axis = common.with_changes(controller=factor * at_slider_gain,
                                       use_estimate=values["pid_feedback"] == "estimated")
            row = loop_figures(axis)
            if row["min_damping"] > 0:
                ipd = analysis.with_reference_filter(axis.loop(), prefilter)
                current = analysis.step_response(ipd, "reference_m", round(LINEAR_WINDOW_S / T))
                row["peak_current_ipd_a_per_m"] = float(np.max(np.abs(
                    current[:, analysis.LOOP_OUTPUTS.index("current_a")])))
            rows.append(row)
    return _designs(rows)


def lqg_front(values: dict) -> Designs:
    """The LQG family on the linear plant with the current filter and noise (cached)."""
    return _lqg_front(tuple(values[name] for name in LQG_FRONT_SETTINGS))


def pid_front(values: dict) -> Designs:
    """The PID family (and its I-PD twins) on the linear plant (cached)."""
    return _pid_front(tuple(values[name] for name in PID_FRONT_SETTINGS))


def fronts(values: dict) -> tuple[Designs, Designs]:
    """Both families (a sweep takes one to two seconds; each family is cached
    per setting it depends on)."""
    return lqg_front(values), pid_front(values)


def pareto(cost: np.ndarray, stiffness: np.ndarray) -> np.ndarray:
    """Indices of the designs on the front (no other is stiffer at no more cost), by rising cost."""
    best, kept = -np.inf, []
    for k in np.argsort(cost):
        if np.isfinite(cost[k]) and stiffness[k] > best:
            best = stiffness[k]
            kept.append(k)
    return np.array(kept, dtype=int)


def stiffness_at(cost: np.ndarray, stiffness: np.ndarray, level: float) -> float:
    """Stiffness on the front at the given cost (linear in log cost between
    front designs); NaN outside the swept range."""
    k = pareto(cost, stiffness)
    if k.size == 0 or not cost[k[0]] <= level <= cost[k[-1]]:
        return float("nan")
    return float(np.interp(np.log(level), np.log(cost[k]), stiffness[k]))


def cost_of(cost: np.ndarray, stiffness: np.ndarray, target: float) -> float:
    """Least cost on the front for the target stiffness (log-linear between the
    front designs either side of it); NaN if the family never reaches it."""
    k = pareto(cost, stiffness)
    above = np.flatnonzero(stiffness[k] >= target)
    if above.size == 0:
        return float("nan")
    j = above[0]
    if j == 0:
        return float(cost[k[0]])
    (c0, c1), (s0, s1) = cost[k[j - 1:j + 1]], stiffness[k[j - 1:j + 1]]
    return float(np.exp(np.log(c0) + (target - s0) / (s1 - s0) * (np.log(c1) - np.log(c0))))


def front_figures(values: dict, pid_noise_a: float) -> dict[str, float]:
    """What the fronts say, as numbers: the LQG/PID step-stiffness ratio at the
    PID design's RMS noise current, and the least peak current on the
    reference step that reaches ``FRONT_STIFFNESS_TARGET_N_PER_M`` per family."""
    lqg, pid_family = fronts(values)
    step_m = values["reference_step_um"] * 1e-6
    L, Pf = lqg.admissible, pid_family.admissible
    return {
        "stiffness_ratio_at_equal_noise":
            stiffness_at(lqg.noise_rms_current_a[L], lqg.step_stiffness_n_per_m[L], pid_noise_a)
            / stiffness_at(pid_family.noise_rms_current_a[Pf], pid_family.step_stiffness_n_per_m[Pf], pid_noise_a),
        "min_dynamic_stiffness_ratio_at_equal_noise":
            stiffness_at(lqg.noise_rms_current_a[L], lqg.min_dynamic_stiffness_n_per_m[L], pid_noise_a)
            / stiffness_at(pid_family.noise_rms_current_a[Pf], pid_family.min_dynamic_stiffness_n_per_m[Pf],
                           pid_noise_a),
        **{f"peak_current_for_target_{name}_a": cost_of(peak[ok] * step_m, stiffness[ok],
                                                       FRONT_STIFFNESS_TARGET_N_PER_M)
           for name, peak, stiffness, ok in (
               ("lqg", lqg.peak_current_a_per_m, lqg.step_stiffness_n_per_m, L),
               ("pid", pid_family.peak_current_a_per_m, pid_family.step_stiffness_n_per_m, Pf),
               ("ipd", pid_family.peak_current_ipd_a_per_m, pid_family.step_stiffness_n_per_m, Pf))},
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


# -- the side-by-side scope ---------------------------------------------------------

SCOPE_COLUMNS = ("x_true_m", "x_estimated_m", "current_a")


class SideBySide:
    """The LQG and the PID loop run in lockstep on the same noise: two
    simulations seeded alike draw identical noise while they advance alike."""

    def __init__(self, simulations: dict[str, AxisSimulation]):
        self.simulations = simulations
        self.sample_time_s = T
        self.columns = ("reference_m", "disturbance_n") + tuple(
            f"{c}_{name.lower()}" for name in simulations for c in SCOPE_COLUMNS)

    def advance(self, n_steps: int) -> np.ndarray:
        first = next(iter(self.simulations.values()))
        reference, disturbance = first.inputs(max(n_steps, 0))
        traces = [sim.advance(n_steps) for sim in self.simulations.values()]
        rows = min(len(trace) for trace in traces)
        parts = [traces[0][:rows, :1], reference[:rows, None], disturbance[:rows, None]]
        parts += [trace[:rows, [1 + TRACE_COLUMNS.index(c) for c in SCOPE_COLUMNS]] for trace in traces]
        return np.hstack(parts)

    def filter_state(self) -> dict | None:
        """The LQG loop's Kalman filter (the one its regulator acts on)."""
        state = self.simulations["LQG"].filter_state()
        return state and {**state, "title": f"LQG loop: {state['title']}"}

    def status_message(self) -> str:
        return " ".join(f"{name} loop: {sim.status_message()}"
                        for name, sim in self.simulations.items() if sim.status != OK)

    def retuned(self, loops: dict[str, AxisSetup]) -> SideBySide:
        return SideBySide({name: sim.retuned(loops[name]) for name, sim in self.simulations.items()})


def side_by_side(values: dict) -> SideBySide:
    return SideBySide({name: AxisSimulation(axis, seed=int(values["seed"]))
                       for name, axis in setups(values).items()})


# -- the paper's claims (paper 000 §IV) -------------------------------------------------

LINEAR = {"force_law": "linear"}
#: Issue's independent check of the printed gains on the linear loop with the eq. 17 filter.
_SI_READING = ("eq. 22 read in SI units: its position and velocity gains lie below the PID's and its "
               "current feedback lowers the amplifier's DC gain by 27 %, so the LQG is the softer loop")
CLAIMS = (
    Claim("paper 000 §IV, eq. 19-22", "LQR gains (K, K_I) of the lab's diagonal Q_J with R_J = 1",
          "K = (9979, 29.686, 0.073), K_I = 1.03·10⁶", "lqr_gain_deviation_from_eq22", (None, 1e-3), "",
          note="largest relative difference of python-control's dlqr from the printed gains"),
    Claim("paper 000 §IV, Fig. 7", "filter's dominant poles over the regulator's (real parts)",
          "more than 5×", "dominant_pole_ratio_filter_to_lqg", (5.0, None), "×"),
    Claim("paper 000 §IV, Fig. 8", "LQG overshoot, 50 µm reference step", "none", "overshoot_lqg_percent",
          (None, 3.0), "%", deviation=True, settings=LINEAR,
          note="the reference enters through the integrator only and the dominant pair has ζ = 0.68: "
               "a small overshoot, not none"),
    Claim("paper 000 §IV, Fig. 8", "peak control current, LQG over PID, 50 µm step", "LQG far below the PID",
          "peak_current_ratio_lqg_to_pid", (None, 0.1), "×", settings=LINEAR),
    Claim("paper 000 §IV, Fig. 8", "settling time (±2 %), LQG over PID", "PID's transient very much longer",
          "settling_time_ratio_lqg_to_pid", (None, 1.0), "×", settings=LINEAR),
    Claim("paper 000 §IV, Fig. 9", "LQG step stiffness Δf/x_max (linear loop)", "s_dyn,LQG = 6.7 N/µm",
          "step_stiffness_lqg_n_per_um", (2.945, 3.255), "N/µm", deviation=True,
          note=_SI_READING + " (independent check: 3.1 N/µm)"),
    Claim("paper 000 §IV, Fig. 9", "PID step stiffness Δf/x_max (linear loop)", "s_dyn,PID = 3.6 N/µm",
          "step_stiffness_pid_n_per_um", (7.315, 8.085), "N/µm", deviation=True,
          note="the printed PID (K = 0.65 on sensor volts) is about twice as stiff as the paper's figure "
               "(independent check: 7.7 N/µm); half its gain gives the paper's value"),
    Claim("paper 000 §IV, Fig. 9", "LQG minimum dynamic stiffness min|F/X(jω)| (linear loop)",
          "s_dyn,LQG = 6.7 N/µm (step definition)", "min_dynamic_stiffness_lqg_n_per_um", (1.9, 2.1), "N/µm",
          deviation=True, note=_SI_READING + " (independent check: 2.0 N/µm)"),
    Claim("paper 000 §IV, Fig. 9", "PID minimum dynamic stiffness min|F/X(jω)| (linear loop)",
          "s_dyn,PID = 3.6 N/µm (step definition)", "min_dynamic_stiffness_pid_n_per_um", (6.555, 7.245), "N/µm",
          deviation=True, note="as for the step stiffness: the printed PID is the stiffer loop "
                               "(independent check: 6.9 N/µm)"),
    Claim("paper 000 §IV, Fig. 9", "PID step stiffness with half the printed gain (K = 0.325)",
          "s_dyn,PID = 3.6 N/µm", "step_stiffness_pid_n_per_um", (3.24, 3.96), "N/µm",
          settings={"pid_gain": 0.325},
          note="the ×½ reading: the paper's PID figure fits a PID with half the printed gain"),
    Claim("paper 000 §IV, Fig. 9", "largest disturbance step the eq. 22 LQG holds (nonlinear plant, eq. 10)",
          "400 N step held", "largest_disturbance_step_lqg_n", (290.0, 330.0), "N", deviation=True,
          note="the softer LQG deflects so far that the force law's negative stiffness grows: it touches "
               "down above about 310 N (the PID holds about 475 N)"),
    Claim("paper 000 §IV, Fig. 9 (redesign preset)", "LQG step stiffness over the PID's, redesigned weights",
          "s_dyn,LQG ≈ 1.9 × s_dyn,PID", "redesign_step_stiffness_ratio_to_pid", (1.0, None), "×",
          deviation=True,
          note="q_x, q_v ×316 and q_ξ ×10 make the LQG as stiff as the printed PID (≥ 7.7 N/µm), at about "
               "2.3× the PID's noise current, not 1.9× stiffer"),
    Claim("paper 000 §IV, Fig. 9 (redesign preset)", "LQG step stiffness, redesigned weights",
          "6.7 N/µm", "redesign_step_stiffness_lqg_n_per_um", (7.7, None), "N/µm",
          note="the redesign target: at least the printed PID's 7.7 N/µm"),
    Claim("paper 000 §IV, Fig. 8 (redesign preset)", "LQG overshoot, redesigned weights", "none",
          "redesign_overshoot_lqg_percent", (None, 2.0), "%"),
    Claim("paper 000 §IV, Fig. 8 (redesign preset)", "LQG peak control current on the 50 µm step, redesigned",
          "LQG far below the PID", "redesign_peak_current_lqg_a", (None, 1.0), "A"),
    Claim("paper 000 §IV, Fig. 7 (redesign preset)", "filter over regulator dominant poles, redesigned",
          "more than 5×", "redesign_dominant_pole_ratio_filter_to_lqg", (5.0, None), "×"),
    Claim("paper 000 §IV, Fig. 9 (trade-off front)", "LQG over PID step stiffness at equal RMS noise current",
          "LQG ≈ 1.9× the PID", "front_step_stiffness_ratio_lqg_to_pid_at_equal_noise", (0.3, 0.6), "×",
          deviation=True,
          note="with these sensors and the eq. 17 filter the LQG buys less stiffness per ampere of noise "
               "than the PID; read at the printed PID's noise current"),
    Claim("paper 000 §IV, Fig. 8 (trade-off front)", "least LQG peak current on the 50 µm step for 10 N/µm",
          "LQG far below the PID", "front_peak_current_for_10_n_per_um_lqg_a", (None, 1.0), "A"),
    Claim("paper 000 §IV, Fig. 8 (trade-off front)", "least PID peak current on the 50 µm step for 10 N/µm",
          "PID far above the LQG", "front_peak_current_for_10_n_per_um_pid_a", (11.9, 16.1), "A",
          note="issue target 14 A ±15 %; the same PIDs as I-PD need as little as the LQG"),
)


# -- the exercise --------------------------------------------------------------------

class LqgVsPid(Exercise):
    name = "lqg_vs_pid"
    title = "LQG regulator against the optimal PID"
    worksheet = "lqg_vs_pid.md"
    parameters = PARAMETERS
    default_duration_s = 1.0
    locus = ("pid_gain", "PID loop with filter")
    #: CLAIMS, plus the PID's side of Fig. 8 (step tests are noise-free, so a short run does).
    claims = CLAIMS + (
        Claim("paper 000 §IV, Fig. 8", "PID peak control current, 50 µm reference step", "far above the LQG's",
              "peak_current_pid_a", (5.0, None), "A", duration_s=0.2),
        Claim("paper 000 §IV, Fig. 8", "PID overshoot, 50 µm reference step", "large, long transient",
              "overshoot_pid_percent", (20, None), "%", duration_s=0.2),
    )
    charts = (
        Chart("Rotor position", "µm", (
            Series("reference", "reference_m", 1e6, COLORS["reference"]),
            Series("PID", "x_true_m_pid", 1e6, COLORS["PID"]),
            Series("LQG", "x_true_m_lqg", 1e6, COLORS["LQG"]))),
        Chart("Control current", "A", (
            Series("PID", "current_a_pid", 1.0, COLORS["PID"]),
            Series("LQG", "current_a_lqg", 1.0, COLORS["LQG"]))),
    )

    def model(self, values: dict) -> dict:
        axis = setups(values)["LQG"]
        A, B, C = (np.asarray(M) for M in (axis.model.A, axis.model.B, axis.model.C))
        A_aug, B_aug = integral_augmented_model(axis.rig)
        lqg = regulator(values)
        states = ["x [m]", "v [m/s]", "i [A]"] + (["x_d [m]"] if A.shape[0] == 4 else [])
        return {"states": states, "inputs": ["i_ref [V]"], "outputs": ["K_mx x_d [V]", "K_mi i [V]"],
                "sample_time_s": T, "A": A.tolist(), "B": B[:, :1].tolist(), "C": C.tolist(),
                "Q": axis.filter_Q.tolist(), "R": axis.filter_R.tolist(),
                "regulator_states": ["x [m]", "v [m/s]", "i [A]", "xi = ∫(r - x) dt [m s]"],
                "A_aug": A_aug.tolist(), "B_aug": B_aug.tolist(),
                "state_gain_K": list(lqg.state_gain), "integral_gain_K_I_v_per_m_s": lqg.integral_gain_v_per_m_s}

    def mode_names(self, values: dict, poles: dict[str, np.ndarray]) -> dict[str, list[str | None]]:
        """The open-loop plant's poles by name (the loops' poles keep their generic kind)."""
        return {"open-loop plant": axis_plant_names(poles["open-loop plant"])}

    def mode_matrices(self, values: dict) -> dict[str, tuple]:
        """The PID loop, the LQG regulator (plant states and the position integrator, eq. 19) and
        the Kalman filter's error (eq. 2), by their states (paper 000)."""
        loops, lqg = setups(values), regulator(values)
        axis = loops["LQG"]
        A_aug, B_aug = integral_augmented_model(axis.rig)
        gain = np.array([*lqg.state_gain, -lqg.integral_gain_v_per_m_s])
        matrices = axis_mode_matrices(loops["PID"], "PID loop with filter")
        matrices.update(axis_mode_matrices(axis, "unused", "Kalman filter error"))
        matrices.pop("unused")
        matrices["LQG regulator"] = (A_aug - B_aug @ gain[None], [*AXIS_STATES[:3], INTEGRAL_STATE], T)
        return matrices

    def locus_matrices(self, values: dict, factors: tuple[float, ...]) -> tuple[list[np.ndarray], float]:
        """The PID loop's state matrices (the states in the feedback) at these PID gains K."""
        axis = setups(values)["PID"]
        return [axis.loop_matrix(factor / values["pid_gain"]) for factor in factors], T

    def open_loops(self, values: dict) -> dict:
        return {name: axis.loop_at_plant_input() for name, axis in setups(values).items()}

    def analyse(self, values: dict):
        """Yields the step tests, the two stiffness definitions and the poles
        first; then the noise-driven RMS values and the largest disturbance step
        a loop survives where the step test lost it; then the trade-off fronts
        (a sweep of about 150 designs, cached per filter and noise setting)."""
        loops, lqg = setups(values), regulator(values)
        tests, poles = step_tests(loops, values), pole_sets(loops, lqg)
        linear = {name: loop_figures(axis) for name, axis in loops.items()}
        readouts = []
        for name in LOOPS:
            # a figure the step test could not measure is a word: the rotor touched down (or never settled)
            word = "touched down" if tests[name]["stops"] else "not reached"
            r = {key: (word if isinstance(value, float) and not np.isfinite(value) else value)
                 for key, value in tests[name].items()}
            f = linear[name]
            readouts += [
                (f"{name}: overshoot, reference step", r["reference_overshoot_percent"], "%"),
                (f"{name}: settling time (±2 %)", _scaled(r["reference_settling_time_s"], 1e3), "ms"),
                (f"{name}: peak control current, reference step", r["reference_peak_current_a"], "A"),
                (f"{name}: RMS control current, reference step", r["reference_rms_current_a"], "A"),
                (f"{name}: step stiffness Δf/x_max (linear)", f["step_stiffness_n_per_m"] * 1e-6, "N/µm"),
                (f"{name}: min dynamic stiffness (linear, worst frequency)", f["min_dynamic_stiffness_n_per_m"] * 1e-6, "N/µm"),
                (f"{name}: frequency of the min dynamic stiffness", f["min_dynamic_stiffness_frequency_hz"], "Hz"),
                (f"{name}: largest deviation, disturbance step", _scaled(r["disturbance_max_deviation_m"], 1e6), "µm"),
                (f"{name}: s_dyn of the time run (chosen plant)",
                 _scaled(r["disturbance_dynamic_stiffness_n_per_m"], 1e-6), "N/µm"),
                (f"{name}: offset 150 ms after the disturbance step", _scaled(r["disturbance_final_offset_m"], 1e6), "µm"),
            ]
        ratio = dominant_pole_ratio(poles)
        readouts += [
            ("Dominant pole, LQG regulator (Re)", dominant_real_part(poles["LQG regulator"]), "rad/s"),
            ("Dominant pole, Kalman filter (Re)", dominant_real_part(poles["Kalman filter error"]), "rad/s"),
            ("Ratio filter / regulator", ratio, "×"),
            ("Dominant pole, whole LQG loop (Re)", dominant_real_part(lqg_loop_poles(loops)), "rad/s"),
            ("LQG gain K_x", lqg.state_gain[0], "V/m"),
            ("LQG gain K_v", lqg.state_gain[1], "V·s/m"),
            ("LQG gain K_i", lqg.state_gain[2], "V/A"),
            ("Integral gain K_I", lqg.integral_gain_v_per_m_s, "V/(m·s)"),
        ]
        notes = [f"{name} loop in the step test: {message}" for name in LOOPS for message in tests[name]["stops"]]
        notes += [
            ("Step figures: noise-free runs of the compiled loop on the chosen plant; "
             "s_dyn = |Δf_z| / largest deviation from the reference (paper §IV)."),
            ("Two stiffness definitions, both on the linear loop with the filter in use: step stiffness = "
             "|Δf| / largest deflection after a force step (Fig. 9); minimum dynamic stiffness = the "
             "smallest |F/X| over frequency (a sinusoidal force at the worst frequency, ISO 14839 style)."),
        ]
        plots = step_plots(tests, values)
        pending_plots = plots + front_plots(values, None)
        pending = [("Noise-driven RMS displacement", "computing …", ""),
                   ("Trade-off fronts", "computing …", "")]
        yield Analysis(readouts + pending, poles, notes, pending_plots)
        readouts += [(f"{name}: noise-driven RMS displacement", linear[name]["noise_rms_x_m"] * 1e6, "µm")
                     for name in LOOPS]
        readouts += [(f"{name}: noise-driven RMS coil current", linear[name]["noise_rms_current_a"], "A")
                     for name in LOOPS]
        for name in LOOPS:
            if tests[name]["stops"]:
                largest = largest_disturbance_step(loops[name])
                readouts.append((f"{name}: largest disturbance step held (chosen plant)", largest, "N"))
                notes.append(f"The {name} loop loses the rotor on the {values['disturbance_step_n']:g} N step; "
                             f"it holds at most {largest:.0f} N on this plant (150 ms, no noise).")
        yield Analysis(readouts + pending[1:], poles, notes, pending_plots)
        lqg_front(values)                       # one family, then a chance to give way to newer settings
        yield Analysis(readouts + pending[1:], poles, notes, pending_plots)
        front = front_figures(values, linear["PID"]["noise_rms_current_a"])
        target = FRONT_STIFFNESS_TARGET_N_PER_M * 1e-6
        readouts += [
            ("Fronts: LQG / PID step stiffness at the PID's noise current",
             front["stiffness_ratio_at_equal_noise"], "×"),
            ("Fronts: LQG / PID min dynamic stiffness at the PID's noise current",
             front["min_dynamic_stiffness_ratio_at_equal_noise"], "×"),
            (f"Fronts: least peak current for {target:g} N/µm, LQG", front["peak_current_for_target_lqg_a"], "A"),
            (f"Fronts: least peak current for {target:g} N/µm, PID", front["peak_current_for_target_pid_a"], "A"),
            (f"Fronts: least peak current for {target:g} N/µm, I-PD", front["peak_current_for_target_ipd_a"], "A"),
        ]
        yield Analysis(readouts, poles, notes, plots + front_plots(values, linear))

    def simulation(self, values: dict) -> SideBySide:
        return side_by_side(values)

    def retune(self, simulation: SideBySide, values: dict) -> SideBySide:
        """A slider move changes the running experiment instead of restarting it."""
        return simulation.retuned(setups(values))

    def report_figures(self, values: dict) -> list:
        """Figs. 8-9: both loops after the reference step and after the disturbance step."""
        from lab_modules.exercises._figures import plot_figure
        return [plot_figure(plot) for plot in step_plots(step_tests(setups(values), values), values)]

    def live_readouts(self, trace: dict[str, np.ndarray]) -> list[tuple[str, float, str]]:
        return [(f"{name}: RMS control current, this run", rms(trace[f"current_a_{name.lower()}"]), "A")
                for name in LOOPS]

    def scene(self, values: dict) -> BearingScene:
        """The LQG loop's rotor in the bearing, the PID loop's rotor as an outline
        (steps of tens of micrometres: drawn ×1000)."""
        return BearingScene(values, exaggeration=1000, force_scale_m_per_n=2e-4,
                            true_column="x_true_m_lqg", current_column="current_a_lqg", rotor_label="LQG",
                            ghosts=(Ghost("LQG estimate", "x_estimated_m_lqg", ESTIMATE_RED),
                                    Ghost("PID rotor", "x_true_m_pid", TRUE_BLUE)),
                            disturbance_n=lambda latest, values: latest["disturbance_n"])

    def metrics(self, values: dict, duration_s: float) -> dict:
        """Headless figures.  Time-run figures of a step test that lost the rotor
        are None, and ``step_test_status_*`` says why and names the largest step
        the loop holds; everything on the linear loop is always a number."""
        loops = setups(values)
        tests, poles = step_tests(loops, values), pole_sets(loops, regulator(values))
        linear = {name: loop_figures(axis) for name, axis in loops.items()}
        designed = lqr_from_weights(values)
        in_use = regulator(values)
        sim = side_by_side({**values, "reference_step_um": 0.0, "disturbance_step_n": 0.0})
        trace = sim.advance(round(duration_s / T))
        steady = trace[min(round(0.1 / T), len(trace) // 5):]        # the filter's start-up dropped
        live = dict(zip(sim.columns, steady[:, 1:].T))
        metrics = {}
        for name in LOOPS:
            r, f, key = tests[name], linear[name], name.lower()
            largest = largest_disturbance_step(loops[name])
            status = []
            if r["stops"]:
                status.append(" ".join(r["stops"]) + f" The loop holds disturbance steps up to {largest:.0f} N "
                              "on this plant; the time-run figures of the stopped test are null.")
            if not r["stops"] and not np.isfinite(r["reference_settling_time_s"]):
                status.append(f"The reference step does not settle within ±{SETTLING_BAND:.0%} in "
                              f"{AFTER_STEP_S * 1e3:.0f} ms: settling time null.")
            metrics.update({
                f"step_stiffness_{key}_n_per_um": f["step_stiffness_n_per_m"] * 1e-6,
                f"min_dynamic_stiffness_{key}_n_per_um": f["min_dynamic_stiffness_n_per_m"] * 1e-6,
                f"min_dynamic_stiffness_frequency_{key}_hz": f["min_dynamic_stiffness_frequency_hz"],
                f"noise_rms_current_linear_{key}_a": f["noise_rms_current_a"],
                f"dynamic_stiffness_{key}_n_per_um": _scaled(r["disturbance_dynamic_stiffness_n_per_m"], 1e-6),
                f"max_deviation_{key}_um": _scaled(r["disturbance_max_deviation_m"], 1e6),
                f"offset_after_disturbance_{key}_um": _scaled(r["disturbance_final_offset_m"], 1e6),
                f"overshoot_{key}_percent": r["reference_overshoot_percent"],
                f"settling_time_{key}_ms": _scaled(r["reference_settling_time_s"], 1e3),
                f"peak_current_{key}_a": r["reference_peak_current_a"],
                f"rms_current_{key}_a": r["reference_rms_current_a"],
                f"peak_current_disturbance_{key}_a": r["disturbance_peak_current_a"],
                f"largest_disturbance_step_{key}_n": largest,
                f"step_test_status_{key}": " ".join(status) or "ok",
                f"noise_rms_displacement_{key}_um": rms(live[f"x_true_m_{key}"]) * 1e6,
                f"noise_rms_current_{key}_a": rms(live[f"current_a_{key}"]),
            })
        redesign = redesign_figures(values)
        front = front_figures(values, linear["PID"]["noise_rms_current_a"])
        metrics.update({
            "peak_current_ratio_lqg_to_pid": metrics["peak_current_lqg_a"] / metrics["peak_current_pid_a"],
            "settling_time_ratio_lqg_to_pid": metrics["settling_time_lqg_ms"] / metrics["settling_time_pid_ms"],
            "dominant_pole_ratio_filter_to_lqg": dominant_pole_ratio(poles),
            "dominant_pole_lqg_rad_per_s": dominant_real_part(poles["LQG regulator"]),
            "dominant_pole_filter_rad_per_s": dominant_real_part(poles["Kalman filter error"]),
            "lqr_gain": [*designed.state_gain, designed.integral_gain_v_per_m_s],
            "lqr_gain_deviation_from_eq22": gain_deviation(designed, PAPER_LQG),
            "lqg_gain_in_use": [*in_use.state_gain, in_use.integral_gain_v_per_m_s],
            "lqr_gain_units": ["V/m", "V s/m", "V/A", "V/(m s)"],
            "lqg_regulator_poles_rad_per_s": kalman_noise.pairs(poles["LQG regulator"]),
            "lqg_loop_poles_rad_per_s": kalman_noise.pairs(lqg_loop_poles(loops)),
            "filter_error_poles_rad_per_s": kalman_noise.pairs(poles["Kalman filter error"]),
            "redesign_weight_factors": list(REDESIGN_FACTORS),
            "redesign_step_stiffness_lqg_n_per_um": redesign["step_stiffness_n_per_m"] * 1e-6,
            "redesign_min_dynamic_stiffness_lqg_n_per_um": redesign["min_dynamic_stiffness_n_per_m"] * 1e-6,
            "redesign_step_stiffness_ratio_to_pid": redesign["step_stiffness_n_per_m"]
                                                    / linear["PID"]["step_stiffness_n_per_m"],
            "redesign_overshoot_lqg_percent": redesign["overshoot_percent"],
            "redesign_peak_current_lqg_a": redesign["peak_current_a_per_m"] * values["reference_step_um"] * 1e-6,
            "redesign_noise_rms_current_lqg_a": redesign["noise_rms_current_a"],
            "redesign_dominant_pole_ratio_filter_to_lqg": redesign["pole_ratio"],
            "front_step_stiffness_ratio_lqg_to_pid_at_equal_noise": front["stiffness_ratio_at_equal_noise"],
            "front_min_dynamic_stiffness_ratio_lqg_to_pid_at_equal_noise":
                front["min_dynamic_stiffness_ratio_at_equal_noise"],
            "front_peak_current_for_10_n_per_um_lqg_a": front["peak_current_for_target_lqg_a"],
            "front_peak_current_for_10_n_per_um_pid_a": front["peak_current_for_target_pid_a"],
            "front_peak_current_for_10_n_per_um_ipd_a": front["peak_current_for_target_ipd_a"],
            "status_noise_run": sim.status_message() or "ok",
            "duration_s": len(trace) * T,
        })
        return {key: None if isinstance(value, float) and not np.isfinite(value) else value
                for key, value in metrics.items()}


def gain_deviation(designed: StateFeedback, printed: StateFeedback) -> float:
    """Largest relative difference between two regulators' four gains (K, K_I)."""
    a = np.array([*designed.state_gain, designed.integral_gain_v_per_m_s])
    b = np.array([*printed.state_gain, printed.integral_gain_v_per_m_s])
    return float(np.max(np.abs(a / b - 1.0)))


def rms(samples: np.ndarray) -> float:
    return float(np.sqrt(np.mean(samples**2))) if samples.size else float("nan")


def sampled(trace: np.ndarray, name: str, rows: np.ndarray, scale: float) -> np.ndarray:
    """Column ``name`` at the given rows, scaled; NaN (a gap) past the end of a stopped run."""
    y = np.full(rows.size, np.nan)
    kept = rows < len(trace)
    y[kept] = column(trace, name)[rows[kept]] * scale
    return y


def step_plots(tests: dict, values: dict) -> list[Plot]:
    """Figs. 8-9: position and control current of both loops after each step."""
    reference_um, force_n = values["reference_step_um"], values["disturbance_step_n"]
    n_rows = round((BEFORE_STEP_S + AFTER_STEP_S) / T)
    rows = np.arange(0, n_rows, max(1, n_rows // PLOT_POINTS))
    t_ms = (rows * T - BEFORE_STEP_S) * 1e3
    plots = []
    for test, title, reference_um_after in (
            ("reference", f"Reference step {reference_um:g} µm (Fig. 8)", reference_um),
            ("disturbance", f"Disturbance step {force_n:g} N (Fig. 9)", 0.0)):
        traces = {name: tests[name][test] for name in LOOPS}
        reference = np.where(t_ms >= 0.0, reference_um_after, 0.0)
        plots.append(Plot(f"{title}: rotor position", "time after the step [ms]", "rotor position x [µm]",
                          t_ms, (("reference", reference, COLORS["reference"]),) + tuple(
                              (name, sampled(trace, "x_true_m", rows, 1e6), COLORS[name])
                              for name, trace in traces.items())))
        plots.append(Plot(f"{title}: control current", "time after the step [ms]", "coil current i [A]",
                          t_ms, tuple((name, sampled(trace, "current_a", rows, 1.0), COLORS[name])
                                      for name, trace in traces.items())))
    return plots



FRONT_COLORS = {"LQG": COLORS["LQG"], "PID": COLORS["PID"], "I-PD": "#2ca02c", "rings": "#c7c7c7",
                "LQG in use": "#5c0000", "PID in use": "#08306b"}
RINGS = f"ζ < {FRONT_MIN_DAMPING:g} (rings)"
#: Series (label, colour) of the front plots, in order.
FRONT_SERIES = {
    "noise": (("LQG designs", FRONT_COLORS["LQG"]), ("PID designs", FRONT_COLORS["PID"]),
              (RINGS, FRONT_COLORS["rings"]), ("LQG in use", FRONT_COLORS["LQG in use"]),
              ("PID in use", FRONT_COLORS["PID in use"])),
    "current": (("LQG designs", FRONT_COLORS["LQG"]), ("PID designs", FRONT_COLORS["PID"]),
                ("I-PD designs", FRONT_COLORS["I-PD"]), (RINGS, FRONT_COLORS["rings"]),
                ("LQG in use", FRONT_COLORS["LQG in use"]), ("PID in use", FRONT_COLORS["PID in use"])),
}


def scatter(title: str, x_label: str, y_label: str,
            groups: list[tuple[str, np.ndarray, np.ndarray, str]]) -> Plot:
    """A scatter plot of several point sets over one shared, sorted x axis
    (each set a series with gaps where the others have their points); points
    with a non-positive or non-finite x or y are left out (log x axis)."""
    kept = []
    for label, x, y, color in groups:
        x, y = np.atleast_1d(np.asarray(x, dtype=float)), np.atleast_1d(np.asarray(y, dtype=float))
        ok = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
        kept.append((label, x[ok], y[ok], color))
    xs = np.concatenate([x for _, x, _, _ in kept])
    if xs.size == 0:                                   # nothing yet: an empty frame on the same axes
        return Plot(title, x_label, y_label, np.array([0.1, 1.0]),
                    tuple((label, np.full(2, np.nan), color) for label, _, _, color in kept),
                    points=True, log_x=True)
    order = np.argsort(xs, kind="stable")
    series, start = [], 0
    for label, x, y, color in kept:
        column = np.full(xs.size, np.nan)
        column[start:start + x.size] = y
        start += x.size
        series.append((label, column[order], color))
    return Plot(title, x_label, y_label, xs[order], tuple(series), points=True, log_x=True)


def front_plots(values: dict, linear: dict[str, dict] | None) -> list[Plot]:
    """The trade-off fronts (Analysis tab): (a) step stiffness against the
    noise-driven RMS coil current, (b) step stiffness against the peak coil
    current on the reference step, (c) minimum dynamic stiffness against the
    RMS noise current; every swept design, the lightly damped ones grey, the
    designs in use marked.  ``linear`` None: the empty frames (still computing)."""
    step_m = values["reference_step_um"] * 1e-6
    titles = ("Trade-off front (a): step stiffness against noise current",
              f"Trade-off front (b): step stiffness against peak current, {values['reference_step_um']:g} µm step",
              "Trade-off front (c): minimum dynamic stiffness against noise current")
    noise_label = "noise-driven RMS coil current [A]"
    current_label = "peak coil current on the reference step [A]"
    step_label, dynamic_label = "step stiffness Δf/x_max [N/µm]", "min dynamic stiffness [N/µm]"
    empty = np.zeros(0)
    if linear is None:                      # same series and colours: the browser keeps the first ones
        return [scatter(title, x_label, y_label, [(label, empty, empty, color) for label, color in series])
                for title, x_label, y_label, series in (
                    (titles[0], noise_label, step_label, FRONT_SERIES["noise"]),
                    (titles[1], current_label, step_label, FRONT_SERIES["current"]),
                    (titles[2], noise_label, dynamic_label, FRONT_SERIES["noise"]))]
    lqg, pid_family = fronts(values)
    L, Pf = lqg.admissible, pid_family.admissible

    def per_um(stiffness):
        return np.asarray(stiffness) * 1e-6

    def noise_front(stiffness_of, key):
        return [
            ("LQG designs", lqg.noise_rms_current_a[L], per_um(stiffness_of(lqg)[L]), FRONT_COLORS["LQG"]),
            ("PID designs", pid_family.noise_rms_current_a[Pf], per_um(stiffness_of(pid_family)[Pf]),
             FRONT_COLORS["PID"]),
            (RINGS,
             np.r_[lqg.noise_rms_current_a[~L], pid_family.noise_rms_current_a[~Pf]],
             per_um(np.r_[stiffness_of(lqg)[~L], stiffness_of(pid_family)[~Pf]]), FRONT_COLORS["rings"]),
            *((f"{name} in use", linear[name]["noise_rms_current_a"], per_um(linear[name][key]),
               FRONT_COLORS[f"{name} in use"]) for name in LOOPS)]

    current = [
        ("LQG designs", lqg.peak_current_a_per_m[L] * step_m, per_um(lqg.step_stiffness_n_per_m[L]),
         FRONT_COLORS["LQG"]),
        ("PID designs", pid_family.peak_current_a_per_m[Pf] * step_m, per_um(pid_family.step_stiffness_n_per_m[Pf]),
         FRONT_COLORS["PID"]),
        ("I-PD designs", pid_family.peak_current_ipd_a_per_m[Pf] * step_m,
         per_um(pid_family.step_stiffness_n_per_m[Pf]), FRONT_COLORS["I-PD"]),
        (RINGS,
         np.r_[lqg.peak_current_a_per_m[~L], pid_family.peak_current_a_per_m[~Pf]] * step_m,
         per_um(np.r_[lqg.step_stiffness_n_per_m[~L], pid_family.step_stiffness_n_per_m[~Pf]]),
         FRONT_COLORS["rings"]),
        *((f"{name} in use", linear[name]["peak_current_a_per_m"] * step_m,
           per_um(linear[name]["step_stiffness_n_per_m"]), FRONT_COLORS[f"{name} in use"]) for name in LOOPS)]
    return [scatter(titles[0], noise_label, step_label,
                    noise_front(lambda d: d.step_stiffness_n_per_m, "step_stiffness_n_per_m")),
            scatter(titles[1], current_label, step_label, current),
            scatter(titles[2], noise_label, dynamic_label,
                    noise_front(lambda d: d.min_dynamic_stiffness_n_per_m, "min_dynamic_stiffness_n_per_m"))]


EXERCISE = LqgVsPid()
