"""Exercise ``ekf_disturbance``: the nonlinear EKF that estimates an unknown
force and reads k_x, k_i from its Jacobian (paper 000, §III-B, Figs. 4-5).

The filter is ``extended_kalman.DisturbanceEKF``: states (x, v, i, x_d, f_z)
(eq. 13), force law eq. 10, sensor lag eq. 12, prediction by RK4, Phi by the
truncated series eq. 15, R and Q of eq. 16-17.  The paper's PID holds the
rotor on the filter's undelayed position estimate (§III-B); the estimated
force can be fed forward as a current (the "disturbance feedforward" the paper
proposes after Fig. 4).

Two experiments:

* ``force_step`` (Fig. 4): a square-wave disturbance force.  q_55 sets how
  fast (and how noisy) the force estimate follows.
* ``gap_sweep`` (Fig. 5): a 200 N static load, then the reference moves the
  rotor sinusoidally across the gap; k_x and k_i are read from Phi by eq. 18
  and compared with the analytic derivatives of eq. 10 at the rotor's true
  position and current.

Settling time of the force estimate: the same run (same noise) with and
without the step; their difference is the estimate's response to the step
alone, and the settling time is when that difference enters and stays in a
band of ±5 % of the step.  The noise of the estimate is reported separately.

Choices not in the paper (worksheet "Choices"):

* T_mx = 200 µs (``radial_bearing.DEFAULT_SENSOR_LAG_S``), in plant and filter.
* q_33 = 1e-3 A² instead of eq. 17's 0.43 A².  The paper's value covers the
  real amplifier's unmodelled behaviour; the simulated amplifier follows eq. 4
  exactly (1 mA noise per sample), so 0.43 A² only lets the 1.87 A current
  sensor noise into i_hat and, through k_x's dependence on i (eq. 10), into
  the factors of eq. 18 (k_x: 19 % RMS error, 4 % bias over the sweep), and
  slows the force estimate (25 ms instead of 5 ms); a worksheet task.  1e-3 A² allows the amplifier model an error of
  1 % of i0 per sample.
* Sweep: ±120 µm (a quarter of the 460 µm gap, where k_x already changes by a
  factor of 2.5), 800 ms period, after the load has ramped in over 50 ms.  The
  paper shows the sweep but gives neither amplitude nor speed.
"""

from __future__ import annotations

from dataclasses import replace

import control
import numpy as np

from lab_modules import analysis
from lab_modules.claims import Claim
from lab_modules.estimators import extended_kalman as ef
from lab_modules.exercises import POLE_MAP, SCOPE, Analysis, Chart, Exercise, Plot, PoleCategory, Series
from lab_modules.exercises._common import (
    AXIS_ERROR_STATES,
    axis_mode_matrices,
    axis_plant_names,
    ekf_loop_fields,
    linear_axis,
)
from lab_modules.exercises._radial_axis_controls import (
    EKF_VARIANCES,
    PAPER_PID,
    PLANT_NOISE,
    SEED,
    TIME_SCALE,
)
from lab_modules.loops.radial_axis_ekf_loop import (
    EKFLoopSetup,
    EKFLoopSimulation,
    Ramp,
    Sine,
    SquareWave,
    Step,
    column,
    loop_at_plant_input,
    no_input,
)
from lab_modules.memo import remembered
from lab_modules.parameters import Parameter, in_si
from lab_modules.plants.radial_bearing import DEFAULT_SENSOR_LAG_S, RIG
from lab_modules.scenes.bearing import ESTIMATE_RED, MEASURED_GREY, BearingScene, Ghost

T = RIG.sample_time_s
SETTLING_BAND = 0.05
STEP_TIME_S = 0.05                  # the metrics' one-shot force step
LOAD_RAMP_S, SWEEP_START_S = 0.05, 0.1
PLOT_POINTS = 800
FIG_4_WINDOW_S = (0.005, 0.06)        # shown before and after the step
#: the pole set of the linearised closed loop (and of its root locus)
CLOSED_LOOP = "closed loop (linearised)"

P = Parameter
PARAMETERS = (
    P("experiment", "Experiment", "", "force_step", choices=("force_step", "gap_sweep"),
      description="force_step: square-wave force (Fig. 4); gap_sweep: static load, rotor moved "
                  "across the gap (Fig. 5).", group="Experiment"),
    P("disturbance_step_n", "Force step Δf_z", "N", 400.0, -1000.0, 1000.0,
      "Height of the disturbance force step (§IV, Fig. 9: 400 N).", step=10.0, group="Experiment"),
    P("step_period_ms", "Step period", "ms", 200.0, 20.0, 2000.0,
      "Period of the square-wave force in the live force_step experiment.", step=10.0, group="Experiment"),
    P("sweep_load_n", "Static load f_z", "N", 200.0, -600.0, 600.0,
      "Static load during the gap sweep (Fig. 5: 200 N).", step=10.0, group="Experiment"),
    P("sweep_amplitude_um", "Sweep amplitude", "µm", 120.0, 10.0, 250.0,
      "Amplitude of the sinusoidal reference that moves the rotor across the gap (not in the paper).",
      step=5.0, group="Experiment"),
    P("sweep_period_ms", "Sweep period", "ms", 800.0, 100.0, 2000.0,
      "Period of the sweep (not in the paper).", step=10.0, group="Experiment"),
    P("filter_q_force", "Filter q_55 (f_z)", "N²", 1.0, 1e-4, 1e4,
      "Process noise of f_z per sample (eq. 17: 1 N²); larger: faster, noisier estimate (Fig. 4).",
      log=True, group="Extended Kalman filter"),
    *EKF_VARIANCES,
    P("filter_sensor_lag_us", "Filter's T_mx", "µs", DEFAULT_SENSOR_LAG_S * 1e6, 50.0, 1000.0,
      "Sensor lag assumed by the filter, eq. 12 (not in the paper; 200 µs).", step=10.0,
      group="Extended Kalman filter"),
    *PLANT_NOISE,
    P("sensor_lag_us", "Plant's sensor lag T_mx", "µs", DEFAULT_SENSOR_LAG_S * 1e6, 0.0, 1000.0,
      "The position sensor's true lag, eq. 12 (not in the paper; 200 µs).", step=10.0, group="Plant"),
    P("feedback", "Feedback source", "", "estimated", choices=("measured", "estimated"),
      description="Position the PID acts on: the delayed measurement or the filter's undelayed "
                  "estimate (§III-B).", group="Controller"),
    P("feedforward", "Force feedforward", "", "off", choices=("off", "on"),
      description="Add -f_z_hat / (k_i K_a) to the amplifier reference (the disturbance feedforward "
                  "proposed after Fig. 4).", group="Controller"),
    *PAPER_PID,
    SEED,
    replace(TIME_SCALE, default=0.1),   # a scope window of 0.5 s
)


def setup(values: dict, experiment: str | None = None, step_n: float | None = None) -> EKFLoopSetup:
    """The experiment described by the parameter values.  ``experiment``
    overrides the choice; "step" is the metrics' one-shot step of ``step_n``."""
    experiment = experiment or values["experiment"]
    si = in_si(PARAMETERS, values)
    if experiment == "gap_sweep":
        reference = Sine(si["sweep_amplitude_um"], si["sweep_period_ms"], SWEEP_START_S)
        disturbance = Ramp(values["sweep_load_n"], LOAD_RAMP_S)
    elif experiment == "step":
        reference, disturbance = no_input, Step(values["disturbance_step_n"] if step_n is None else step_n, STEP_TIME_S)
    else:
        reference, disturbance = no_input, SquareWave(values["disturbance_step_n"], si["step_period_ms"])
    return EKFLoopSetup(
        model=ef.NONLINEAR,
        filter_x0=np.zeros(ef.N_STATES),
        filter_P0=np.diag([10e-6, 1e-3, 0.1, 10e-6, 100.0]) ** 2,
        filter_Q=np.diag([0.0, values["filter_q_velocity"], values["filter_q_current"], 0.0,
                          values["filter_q_force"]]),
        filter_sensor_lag_s=si["filter_sensor_lag_us"],
        plant_sensor_lag_s=si["sensor_lag_us"],
        feedforward=values["feedforward"] == "on",
        **ekf_loop_fields(values),
        reference=reference, disturbance=disturbance, experiment=experiment)


def _run(axis: EKFLoopSetup, seed: int, duration_s: float) -> tuple[np.ndarray, str]:
    sim = EKFLoopSimulation(axis, seed=seed)
    return sim.advance(round(duration_s / T)), sim.status_message()


@remembered(size=16)
def step_run(values: dict, step_n: float, duration_s: float) -> tuple[np.ndarray, str]:
    """The one-shot experiment with a step of ``step_n`` [N] (remembered: the run without the step
    does not depend on the step's height, and a move of the step leaves it as it was)."""
    return _run(setup(values, "step", step_n), int(values["seed"]), duration_s)


def force_step(values: dict, duration_s: float = 0.25) -> dict:
    """Fig. 4: the force estimate's response to a one-shot step (see module docstring)."""
    step_n = values["disturbance_step_n"]
    with_step, status = step_run(values, step_n, duration_s)
    without, _ = step_run(values, 0.0, duration_s)
    n = min(len(with_step), len(without))
    t = with_step[:n, 0]
    response = column(with_step, "force_estimated_n")[:n] - column(without, "force_estimated_n")[:n]
    after = t >= STEP_TIME_S
    outside = np.flatnonzero(after & (np.abs(response - step_n) > SETTLING_BAND * abs(step_n)))
    if status or n == 0 or (outside.size and outside[-1] == n - 1):
        settling_ms = float("nan")
    else:
        settling_ms = 1e3 * (t[outside[-1] + 1] - STEP_TIME_S) if outside.size else 0.0
    before = t < STEP_TIME_S
    x = column(with_step, "x_true_m")[:n]
    return {"settling_ms": settling_ms, "t": t, "response": response, "status": status or "ok",
            "estimate": column(with_step, "force_estimated_n")[:n],
            "noise_n": float(np.std(column(without, "force_estimated_n")[:n][before & (t > 0.02)])),
            "final_error_percent": float(100 * (np.mean(response[-200:]) / step_n - 1)) if step_n else 0.0,
            "peak_displacement_um": float(1e6 * np.max(np.abs(x[after]))) if after.any() else float("nan")}


@remembered(size=16)
def gap_sweep(values: dict) -> dict:
    """Fig. 5: the factors of eq. 18 against the analytic derivatives of eq. 10
    over one sweep period (samples after the load ramp and the first 10 ms)."""
    duration = SWEEP_START_S + in_si(PARAMETERS, values)["sweep_period_ms"]
    trace, status = _run(setup(values, "gap_sweep"), int(values["seed"]), duration)
    keep = trace[:, 0] >= SWEEP_START_S
    out = {"status": status or "ok", "t": trace[keep, 0], "x_um": 1e6 * column(trace, "x_true_m")[keep]}
    for name, unit in (("kx", "n_per_m"), ("ki", "n_per_a")):
        phi, true = column(trace, f"{name}_estimated_{unit}")[keep], column(trace, f"{name}_true_{unit}")[keep]
        error = 100.0 * (phi / true - 1.0)
        out[name] = (phi, true)
        out[f"{name}_max_error_percent"] = float(np.max(np.abs(error))) if error.size else float("nan")
        out[f"{name}_rms_error_percent"] = float(np.sqrt(np.mean(error**2))) if error.size else float("nan")
    return out


def filter_poles(values: dict) -> np.ndarray:
    """Continuous-equivalent poles of the steady-state filter linearised at the
    centre (x = 0, i = 0): eigenvalues of ``filter_error_matrix``."""
    return analysis.z_to_s(np.linalg.eigvals(filter_error_matrix(values)), T)


def filter_error_matrix(values: dict) -> np.ndarray:
    """Phi - L G of the steady-state filter linearised at the centre (x = 0, i = 0), its
    states (x, v, i, x_d, f_z) of eq. 13, L from python-control's dlqe."""
    physics = ef.physics_vector(RIG, in_si(PARAMETERS, values)["filter_sensor_lag_us"])
    F, Phi = np.zeros((ef.N_STATES, ef.N_STATES)), np.zeros((ef.N_STATES, ef.N_STATES))
    ef.jacobian(ef.NONLINEAR, np.zeros(ef.N_STATES), physics, F)
    ef.transition_matrix(F, T, Phi)
    G = ef.measurement_matrix(ef.NONLINEAR)
    Q = np.diag([0.0, values["filter_q_velocity"], values["filter_q_current"], 0.0, values["filter_q_force"]])
    R = np.diag([values["filter_r_position"], values["filter_r_current"]])
    L, _, _ = control.dlqe(Phi, np.eye(ef.N_STATES), G, Q, R)
    return Phi - L @ G


def fig_4_plot(values: dict, step: dict) -> Plot:
    """Fig. 4: the force estimate (noise included) around the step for q_55 / 100,
    q_55 and 100 q_55, all on the same noise."""
    q55, seed = values["filter_q_force"], int(values["seed"])
    t = step["t"]
    window = (t >= STEP_TIME_S - FIG_4_WINDOW_S[0]) & (t < STEP_TIME_S + FIG_4_WINDOW_S[1])
    duration = STEP_TIME_S + FIG_4_WINDOW_S[1]
    series = [("true step", np.where(t[window] >= STEP_TIME_S, values["disturbance_step_n"], 0.0), "#1f77b4")]
    for factor, color in ((0.01, "#9467bd"), (1.0, "#d62728"), (100.0, "#ff7f0e")):
        if factor == 1.0:
            estimate = step["estimate"]
        else:
            trace, _ = _run(setup({**values, "filter_q_force": q55 * factor}, "step"), seed, duration)
            estimate = np.full(t.size, np.nan)
            estimate[:len(trace)] = column(trace, "force_estimated_n")[:t.size]
        series.append((f"estimate, q_55 = {q55 * factor:.3g} N²", estimate[window], color))
    return Plot(f"Force estimate after a {values['disturbance_step_n']:g} N step (Fig. 4)",
                "time after the step [ms]", "f_z estimate [N]", 1e3 * (t[window] - STEP_TIME_S), tuple(series))


def fig_5_plots(values: dict, sweep: dict) -> list[Plot]:
    """Fig. 5: rotor position, and k_x, k_i from Phi (eq. 18) against eq. 10's derivatives, over time."""
    if not sweep["x_um"].size:
        return []
    pick = np.linspace(0, sweep["x_um"].size - 1, min(PLOT_POINTS, sweep["x_um"].size)).astype(int)
    t_ms = 1e3 * sweep["t"][pick]
    load = f"{values['sweep_load_n']:g} N static load"
    return [
        Plot(f"Rotor moved across the gap, {load} (Fig. 5, top)", "time [ms]", "rotor position x [µm]", t_ms,
             (("true position", sweep["x_um"][pick], "#1f77b4"),)),
        Plot("Force-position factor (Fig. 5, middle)", "time [ms]", "k_x [N/µm]", t_ms,
             (("analytic, eq. 10 at the true (x, i)", sweep["kx"][1][pick] * 1e-6, "#1f77b4"),
              ("from Φ, eq. 18", sweep["kx"][0][pick] * 1e-6, "#d62728"))),
        Plot("Force-current factor (Fig. 5, bottom)", "time [ms]", "k_i [N/A]", t_ms,
             (("analytic, eq. 10 at the true (x, i)", sweep["ki"][1][pick], "#1f77b4"),
              ("from Φ, eq. 18", sweep["ki"][0][pick], "#d62728"))),
    ]


Q33_NOTE = ("measured with q_33 = 1e-3 A², not eq. 17's 0.43 A²: the simulated amplifier follows eq. 4 "
            "exactly, and with 0.43 A² the current estimate follows the current-sensor noise")
CLAIMS = (
    Claim("paper 000 §III-B, Fig. 4", "force estimate settling within ±5 % after a 400 N step (q_55 = 1 N²)",
          "fast, speed set by q_55 (no number)", "disturbance_estimate_settling_ms", (None, 10), "ms",
          note="difference of the estimate with and without the step (same noise), within ±5 % from then on"),
    Claim("paper 000 §III-B, Fig. 4", "force estimate settling with a small q_55", "slower (no number)",
          "disturbance_estimate_settling_ms", (20, None), "ms", settings={"filter_q_force": 0.01}),
    Claim("paper 000 §III-B, eq. 18, Fig. 5", "largest k_x error from Φ over the ±120 µm sweep at 200 N",
          "follows the operating point (no number)", "kx_from_phi_max_error_percent", (None, 2), "%",
          deviation=True, note=Q33_NOTE),
    Claim("paper 000 §III-B, eq. 18, Fig. 5", "largest k_i error from Φ over the sweep",
          "follows the operating point (no number)", "ki_from_phi_max_error_percent", (None, 2), "%",
          deviation=True, note=Q33_NOTE),
)


class EkfDisturbance(Exercise):
    name = "ekf_disturbance"
    title = "Nonlinear EKF: disturbance force and k_x, k_i from Φ"
    worksheet = "ekf_disturbance.md"
    parameters = PARAMETERS
    default_duration_s = 0.25
    min_duration_s = 0.1             # the force step comes at STEP_TIME_S = 0.05 s; 50 ms of its response
    claims = CLAIMS
    locus = ("pid_gain", CLOSED_LOOP)
    key_readouts = ("Force estimate settling (±5 %)", "Force estimate noise σ",
                    "Peak displacement after the step")
    charts = (
        Chart("Disturbance force f_z", "N", (
            Series("estimate", "force_estimated_n", 1.0, "#d62728"),
            Series("true", "force_true_n", 1.0, "#1f77b4")),
            band=("force_estimated_n", "force_sigma_n")),
        Chart("Rotor position", "µm", (
            Series("measured (delayed)", "x_measured_m", 1e6, "#b0b0b0"),
            Series("true", "x_true_m", 1e6, "#1f77b4"),
            Series("estimated", "x_estimated_m", 1e6, "#d62728")),
            band=("x_estimated_m", "x_sigma_m")),
        Chart("k_x from Φ (eq. 18)", "N/µm", (
            Series("from Φ", "kx_estimated_n_per_m", 1e-6, "#d62728"),
            Series("analytic at true (x, i)", "kx_true_n_per_m", 1e-6, "#1f77b4"))),
        Chart("k_i from Φ (eq. 18)", "N/A", (
            Series("from Φ", "ki_estimated_n_per_a", 1.0, "#d62728"),
            Series("analytic at true (x, i)", "ki_true_n_per_a", 1.0, "#1f77b4"))),
        Chart("Coil current", "A", (Series("control current i", "current_a", 1.0, "#2ca02c"),)),
    )

    def model(self, values: dict) -> dict:
        axis = setup(values)
        return {"filter": "extended Kalman filter, nonlinear model eq. 13-15",
                "states": ["x [m]", "v [m/s]", "i [A]", "x_d [m]", "f_z [N]"],
                "inputs": ["i_ref [V]"], "outputs": ["K_mx x_d [V]", "K_mi i [V]"], "sample_time_s": T,
                "prediction": "RK4 of eq. 14 over T; Phi = I + F T + F^2 T^2 / 2 (eq. 15); Gamma = G",
                "sensor_lag_s": axis.filter_sensor_lag_s,
                "G": ef.measurement_matrix(ef.NONLINEAR).tolist(),
                "Q": axis.filter_Q.tolist(), "R": np.diag(axis.filter_R_diag).tolist(),
                "P0": axis.filter_P0.tolist()}

    def open_loops(self, values: dict) -> dict:
        """The PID loop linearised at the centre (x = 0), the EKF at its steady state there."""
        feedforward = " + feedforward" if values["feedforward"] == "on" else ""
        return {f"PID, {values['feedback']} x{feedforward}": loop_at_plant_input(setup(values))}

    def analyse_panel(self, values: dict, panel: str) -> Analysis:
        """The Scope: the force step's figures (two short runs); the Pole map: the linearised loop's,
        the plant's and the filter's poles; the Analysis tab: the gap sweep's k_x, k_i errors and
        Fig. 4-5."""
        if panel == SCOPE:
            step = force_step(values)
            return Analysis([("Force estimate settling (±5 %)", step["settling_ms"], "ms"),
                             ("Force estimate noise σ", step["noise_n"], "N"),
                             ("Peak displacement after the step", step["peak_displacement_um"], "µm")],
                            {}, [f"Force step: {step['status']}"])
        if panel == POLE_MAP:
            plant = RIG.continuous_model(in_si(PARAMETERS, values)["sensor_lag_us"])
            return Analysis([], {"open-loop plant": np.linalg.eigvals(np.asarray(plant.A)),
                                 CLOSED_LOOP: analysis.z_to_s(analysis.loop_poles(linear_axis(values).loop()), T),
                                 "filter error (at x = 0)": filter_poles(values)})
        sweep = gap_sweep(values)
        readouts = [("k_x from Φ: max error over the sweep", sweep["kx_max_error_percent"], "%"),
                    ("k_i from Φ: max error over the sweep", sweep["ki_max_error_percent"], "%")]
        notes = [f"Gap sweep: {sweep['status']}",
                 ("Eq. 18 returns exactly the derivatives of eq. 10 at the filter's estimate (x_hat, i_hat); "
                  "its error against the truth is the estimate's error, mostly that of i_hat."),
                 ("Closed-loop poles (linearised at x = 0): the PID on the rig's linear model (eq. 3-4) with "
                  "the plant's sensor lag, fed by a steady-state Kalman filter of x, v, i with the same q_22, "
                  "q_33 and R; the force state f_z and its feedforward are left out.")]
        return Analysis(readouts, {}, notes, [fig_4_plot(values, force_step(values)), *fig_5_plots(values, sweep)])

    def mode_matrices(self, values: dict) -> dict[str, tuple]:
        """The linearised loop (paper 000 eq. 1-4, 12-13; PID §IV) and the EKF's error at the centre
        (eq. 13: x, v, i, x_d and the force state f_z) by their states."""
        states = [*AXIS_ERROR_STATES, ("f_z error [N]", "disturbance-force estimate error")]
        return {**axis_mode_matrices(linear_axis(values), CLOSED_LOOP),
                "filter error (at x = 0)": (filter_error_matrix(values), states, T)}

    def pole_categories(self, values: dict) -> dict[str, PoleCategory]:
        return {"open-loop plant": PoleCategory.PLANT, CLOSED_LOOP: PoleCategory.CLOSED_LOOP,
                "filter error (at x = 0)": PoleCategory.FILTER_ERROR}

    def mode_names(self, values: dict, poles: dict[str, np.ndarray]) -> dict[str, list[str | None]]:
        """The open-loop plant's poles by name (the loops' poles keep their generic kind)."""
        return {"open-loop plant": axis_plant_names(poles["open-loop plant"])}

    def locus_matrices(self, values: dict, factors: tuple[float, ...]) -> tuple[list[np.ndarray], float]:
        """The linearised loop's state matrices (the states in the feedback) at these PID gains K."""
        axis = linear_axis(values)
        return [axis.loop_matrix(factor / values["pid_gain"]) for factor in factors], T

    def simulation(self, values: dict) -> EKFLoopSimulation:
        return EKFLoopSimulation(setup(values), seed=int(values["seed"]))

    def retune(self, simulation: EKFLoopSimulation, values: dict) -> EKFLoopSimulation:
        """A slider move changes the running experiment; a new experiment starts its inputs now."""
        return simulation.retuned(setup(values))

    def scene(self, values: dict) -> BearingScene:
        """The bearing with the force steps f_z (tens of micrometres: drawn ×1000)."""
        return BearingScene(values, exaggeration=1000, force_scale_m_per_n=2e-4,
                            true_column="x_true_m", current_column="current_a",
                            ghosts=(Ghost("measured", "x_measured_m", MEASURED_GREY),
                                    Ghost("estimate", "x_estimated_m", ESTIMATE_RED)),
                            disturbance_n=lambda latest, values: latest["force_true_n"])

    def metrics(self, values: dict, duration_s: float) -> dict:
        step, sweep = force_step(values, duration_s), gap_sweep(values)
        return {
            "disturbance_estimate_settling_ms": step["settling_ms"],
            "disturbance_estimate_final_error_percent": step["final_error_percent"],
            "disturbance_estimate_noise_n": step["noise_n"],
            "peak_displacement_after_step_um": step["peak_displacement_um"],
            "kx_from_phi_max_error_percent": sweep["kx_max_error_percent"],
            "ki_from_phi_max_error_percent": sweep["ki_max_error_percent"],
            "kx_from_phi_rms_error_percent": sweep["kx_rms_error_percent"],
            "ki_from_phi_rms_error_percent": sweep["ki_rms_error_percent"],
            "sweep_kx_range_n_per_um": [float(np.min(sweep["kx"][1]) * 1e-6), float(np.max(sweep["kx"][1]) * 1e-6)]
            if sweep["x_um"].size else [],
            "sweep_ki_range_n_per_a": [float(np.min(sweep["ki"][1])), float(np.max(sweep["ki"][1]))]
            if sweep["x_um"].size else [],
            "settling_criterion": (f"difference of the force estimate with and without the step (same noise) "
                                   f"within ±{100 * SETTLING_BAND:g} % of the step from then on"),
            "status_force_step": step["status"], "status_gap_sweep": sweep["status"],
            "duration_s": duration_s,
        }

    def report_figures(self, values: dict) -> list:
        """Fig. 4 (force estimate after the step) and Fig. 5 (k_x, k_i from Φ across the gap)."""
        from lab_modules.exercises._figures import analysis_plots, plot_figure
        return [plot_figure(plot) for plot in analysis_plots(self, values)]

    def live_readouts(self, trace: dict[str, np.ndarray]) -> list[tuple[str, float, str]]:
        """Means over the last millisecond of the scope."""
        if len(trace.get("force_true_n", ())) == 0:
            return []
        recent = slice(-round(1e-3 / T), None)
        readouts = [("Force estimate", float(np.mean(trace["force_estimated_n"][recent])), "N"),
                    ("True force", float(np.mean(trace["force_true_n"][recent])), "N")]
        for label, name, unit in (("k_x from Φ error", "kx", "n_per_m"), ("k_i from Φ error", "ki", "n_per_a")):
            ratio = trace[f"{name}_estimated_{unit}"][recent] / trace[f"{name}_true_{unit}"][recent]
            readouts.append((label, float(100.0 * (np.mean(ratio) - 1.0)), "%"))
        return readouts


EXERCISE = EkfDisturbance()
