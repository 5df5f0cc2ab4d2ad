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
the rotor is outside ±2 % of the reference step.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from lab_modules import analysis
from lab_modules.controllers.lqr import (
    PAPER_LQG,
    PAPER_LQR_WEIGHTS,
    StateFeedback,
    integral_augmented_model,
    lqr,
)
from lab_modules.exercises import Analysis, Chart, Exercise, Plot, Series, kalman_noise
from lab_modules.exercises._common import pid_from_values
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
PLOT_POINTS = 500

_kalman_noise = {p.name: p for p in kalman_noise.PARAMETERS}
P = Parameter
PARAMETERS = (
    P("lqg_gains", "LQG gains", "", "paper eq. 22", choices=("paper eq. 22", "LQR from Q_J, R_J"),
      description="The paper's K = (9979, 29.686, 0.073), K_I = 1.03e6, or dlqr with the weights below.",
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
    """The LQG's state feedback: eq. 22 as printed, or eq. 19-21 for the set weights."""
    if values["lqg_gains"] == "paper eq. 22":
        return PAPER_LQG
    return lqr_from_weights(values)


def lqr_from_weights(values: dict) -> StateFeedback:
    weights = tuple(values[name] for name in ("q_position", "q_velocity", "q_current", "q_integral"))
    return lqr(weights, values["r_control"])


def setups(values: dict) -> dict[str, AxisSetup]:
    """The LQG and the PID loop: same rig, noise, filter and excitation."""
    scope_reference = values["scope_excitation"] == "reference step"
    common = AxisSetup(
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
    lqg = regulator(values)
    pid = pid_from_values(values)
    return {
        "LQG": common.with_changes(controller=lqg.integrator(), state_gain=lqg.state_gain,
                                   use_estimate=values["integrator_input"] == "estimated"),
        "PID": common.with_changes(controller=pid, use_estimate=values["pid_feedback"] == "estimated"),
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


# -- poles (Fig. 7) --------------------------------------------------------------------

def pole_sets(loops: dict[str, AxisSetup], lqg: StateFeedback) -> dict[str, np.ndarray]:
    """Continuous-equivalent poles [rad/s], drawn in this order (later on top):
    the open-loop plant, the PID loop, the regulator A_aug - B_aug K on the
    nominal model (Fig. 7's "LQG controlled system") and the steady-state
    filter's error poles eig(A - A K_f C).  With the integrator on the estimate
    the LQG loop's poles are exactly the last two sets (separation principle)."""
    axis = loops["LQG"]
    A_aug, B_aug = integral_augmented_model(axis.rig)
    gain = np.array([*lqg.state_gain, -lqg.integral_gain_v_per_m_s])
    K_f, _ = axis.steady_state_filter
    A, C = np.asarray(axis.model.A), np.asarray(axis.model.C)
    return {
        "open-loop plant": np.linalg.eigvals(np.asarray(RIG.continuous_model(axis.sensor_lag_s).A)),
        "PID loop with filter": analysis.z_to_s(analysis.loop_poles(loops["PID"].loop()), T),
        "LQG regulator": analysis.z_to_s(np.linalg.eigvals(A_aug - B_aug @ gain[None]), T),
        "Kalman filter error": analysis.z_to_s(np.linalg.eigvals(A - A @ K_f @ C), T),
    }


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

    def status_message(self) -> str:
        return " ".join(f"{name} loop: {sim.status_message()}"
                        for name, sim in self.simulations.items() if sim.status != OK)

    def retuned(self, loops: dict[str, AxisSetup]) -> SideBySide:
        return SideBySide({name: sim.retuned(loops[name]) for name, sim in self.simulations.items()})


def side_by_side(values: dict) -> SideBySide:
    return SideBySide({name: AxisSimulation(axis, seed=int(values["seed"]))
                       for name, axis in setups(values).items()})


# -- the exercise --------------------------------------------------------------------

class LqgVsPid(Exercise):
    name = "lqg_vs_pid"
    title = "LQG regulator against the optimal PID"
    worksheet = "lqg_vs_pid.md"
    parameters = PARAMETERS
    default_duration_s = 1.0
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

    def open_loops(self, values: dict) -> dict:
        return {name: axis.loop_at_plant_input() for name, axis in setups(values).items()}

    def analyse(self, values: dict):
        """Yields the step tests and poles first, then adds the noise-driven
        RMS displacement (two Lyapunov solves)."""
        loops, lqg = setups(values), regulator(values)
        tests, poles = step_tests(loops, values), pole_sets(loops, lqg)
        readouts = []
        for name in LOOPS:
            r = tests[name]
            readouts += [
                (f"{name}: overshoot, reference step", r["reference_overshoot_percent"], "%"),
                (f"{name}: settling time (±2 %)", r["reference_settling_time_s"] * 1e3, "ms"),
                (f"{name}: peak control current, reference step", r["reference_peak_current_a"], "A"),
                (f"{name}: RMS control current, reference step", r["reference_rms_current_a"], "A"),
                (f"{name}: largest deviation, disturbance step", r["disturbance_max_deviation_m"] * 1e6, "µm"),
                (f"{name}: dynamic stiffness s_dyn", r["disturbance_dynamic_stiffness_n_per_m"] * 1e-6, "N/µm"),
                (f"{name}: offset 150 ms after the disturbance step", r["disturbance_final_offset_m"] * 1e6, "µm"),
            ]
        readouts += [
            ("Dominant pole, LQG regulator (Re)", dominant_real_part(poles["LQG regulator"]), "rad/s"),
            ("Dominant pole, Kalman filter (Re)", dominant_real_part(poles["Kalman filter error"]), "rad/s"),
            ("Ratio filter / regulator", dominant_pole_ratio(poles), "×"),
            ("Dominant pole, whole LQG loop (Re)", dominant_real_part(lqg_loop_poles(loops)), "rad/s"),
            ("LQG gain K_x", lqg.state_gain[0], "V/m"),
            ("LQG gain K_v", lqg.state_gain[1], "V·s/m"),
            ("LQG gain K_i", lqg.state_gain[2], "V/A"),
            ("Integral gain K_I", lqg.integral_gain_v_per_m_s, "V/(m·s)"),
        ]
        notes = [f"{name} loop in the step test: {message}" for name in LOOPS for message in tests[name]["stops"]]
        notes.append("Step figures: noise-free runs of the compiled loop on the chosen plant; "
                     "s_dyn = |Δf_z| / largest deviation from the reference (paper §IV).")
        plots = step_plots(tests, values)
        yield Analysis(readouts + [("Noise-driven RMS displacement", float("nan"), "computing …")],
                       poles, notes, plots)
        yield Analysis(readouts + [(f"{name}: noise-driven RMS displacement", axis.noise_rms()["x_m"] * 1e6, "µm")
                                   for name, axis in loops.items()], poles, notes, plots)

    def simulation(self, values: dict) -> SideBySide:
        return side_by_side(values)

    def retune(self, simulation: SideBySide, values: dict) -> SideBySide:
        """A slider move changes the running experiment instead of restarting it."""
        return simulation.retuned(setups(values))

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
        loops = setups(values)
        tests, poles = step_tests(loops, values), pole_sets(loops, regulator(values))
        designed = lqr_from_weights(values)
        in_use = regulator(values)
        sim = side_by_side({**values, "reference_step_um": 0.0, "disturbance_step_n": 0.0})
        trace = sim.advance(round(duration_s / T))
        steady = trace[min(round(0.1 / T), len(trace) // 5):]        # the filter's start-up dropped
        live = dict(zip(sim.columns, steady[:, 1:].T))
        metrics = {}
        for name in LOOPS:
            r, key = tests[name], name.lower()
            metrics.update({
                f"dynamic_stiffness_{key}_n_per_um": r["disturbance_dynamic_stiffness_n_per_m"] * 1e-6,
                f"max_deviation_{key}_um": r["disturbance_max_deviation_m"] * 1e6,
                f"offset_after_disturbance_{key}_um": r["disturbance_final_offset_m"] * 1e6,
                f"overshoot_{key}_percent": r["reference_overshoot_percent"],
                f"settling_time_{key}_ms": r["reference_settling_time_s"] * 1e3,
                f"peak_current_{key}_a": r["reference_peak_current_a"],
                f"rms_current_{key}_a": r["reference_rms_current_a"],
                f"peak_current_disturbance_{key}_a": r["disturbance_peak_current_a"],
                f"step_test_status_{key}": " ".join(r["stops"]) or "ok",
                f"noise_rms_displacement_{key}_um": rms(live[f"x_true_m_{key}"]) * 1e6,
                f"noise_rms_current_{key}_a": rms(live[f"current_a_{key}"]),
            })
        metrics.update({
            "dominant_pole_ratio_filter_to_lqg": dominant_pole_ratio(poles),
            "dominant_pole_lqg_rad_per_s": dominant_real_part(poles["LQG regulator"]),
            "dominant_pole_filter_rad_per_s": dominant_real_part(poles["Kalman filter error"]),
            "lqr_gain": [*designed.state_gain, designed.integral_gain_v_per_m_s],
            "lqg_gain_in_use": [*in_use.state_gain, in_use.integral_gain_v_per_m_s],
            "lqr_gain_units": ["V/m", "V s/m", "V/A", "V/(m s)"],
            "lqg_regulator_poles_rad_per_s": kalman_noise.pairs(poles["LQG regulator"]),
            "lqg_loop_poles_rad_per_s": kalman_noise.pairs(lqg_loop_poles(loops)),
            "filter_error_poles_rad_per_s": kalman_noise.pairs(poles["Kalman filter error"]),
            "status_noise_run": sim.status_message() or "ok",
            "duration_s": len(trace) * T,
        })
        return metrics


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


EXERCISE = LqgVsPid()
