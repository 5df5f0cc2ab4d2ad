"""Exercise ``maglev_tracking``: feedback-linearising control of the maglev
ball with a continuous-discrete EKF (paper 004, Henley, §2.3-2.5, §3.1-3.2).

The ball (Table 3.1) hangs 14.8 mm under the coil.  The controller of
eq. 2.21-2.30 needs position, velocity and current; only the position is
measured, so the EKF of eq. 2.40-2.45 estimates the rest.  References: the
2 mm step of §3.1.2 (the paper zeroes its derivatives; a fourth-order
prefilter is the smooth alternative), the 1 mm, 10 rad/s sine of §3.1.3, and
the 0.05 mm square and sine waves the hardware tracked in §3.7.

Views: reference, true, measured and estimated position; the estimation
errors of position and velocity inside the filter's ±3σ (Fig. 3.3, 3.5);
current and coil voltage.  The analysis tab plots the voltage the controller
asks for as the estimated current falls towards the singular region x3 -> 0.
"""

from __future__ import annotations

from dataclasses import replace

import control
import numpy as np

from lab_modules.claims import Claim
from lab_modules.controllers.feedback_linearisation import (
    GUARD_CURRENT_A,
    brunovsky_chain,
    decoupling_gain_v_per_m_s3,
    linearising_control,
)
from lab_modules.controllers.lead_lag import LEAD_LAG
from lab_modules.exercises import Analysis, Chart, Exercise, Plot, PoleCategory, Series
from lab_modules.exercises._common import MAGLEV_LAGS, magnet_plant_names
from lab_modules.loops.maglev_loop import (
    CONTROLLERS,
    FILTERS,
    MaglevSetup,
    MaglevSimulation,
    Reference,
    loop_at_plant_input,
    preset_q,
    record_lead_lag_run,
)
from lab_modules.parameters import Parameter, ParameterError, in_si
from lab_modules.plants.maglev_ball import TABLE_3_1
from lab_modules.recordings import to_csv
from lab_modules.scenes.maglev import Columns, DrawingScale, MaglevScene, exaggeration_for

T = TABLE_3_1.sample_time_s
GAP_M = TABLE_3_1.operating_gap_m
#: Table 3.1: plant at (14.8 mm, 0, 0.89409 A), estimator at (14.367 mm, 0, 0.9388 A).
PAPER_POSITION_ERROR_MM = (0.014367 - 0.0148) * 1e3
PAPER_CURRENT_ERROR_PERCENT = (0.9388 / 0.89409 - 1.0) * 100
REFERENCES = {
    "step_2mm": {"kind": "step", "amplitude_m": 2e-3},
    "sine_1mm": {"kind": "sine", "amplitude_m": 1e-3, "frequency_rad_s": 10.0},
    "square_0.05mm": {"kind": "square", "amplitude_m": 0.05e-3},
    "sine_0.05mm": {"kind": "sine", "amplitude_m": 0.05e-3},
}
Q_PRESETS = ("table_3.1", "eq_3.4", "custom")
SETTLE_S = 0.25          # "after convergence": the filter and the loop settle within 0.25 s (Fig. 3.3)

P = Parameter
PARAMETERS = (
    P("reference", "Reference", "", "step_2mm", choices=tuple(REFERENCES),
      description="2 mm step at 0.75 s (§3.1.2), 1 mm 10 rad/s sine (§3.1.3), 0.05 mm square or sine "
                  "around 14.8 mm (hardware, §3.7).", group="Reference"),
    P("step_derivatives", "Step/square derivatives", "", "zeroed", choices=("zeroed", "prefilter"),
      description="zeroed: the paper's choice (y_R' = y_R'' = y_R''' = 0 while y_R jumps); prefilter: "
                  "the reference through w^4/(s+w)^4, smooth with exact derivatives.", group="Reference"),
    P("prefilter_bandwidth_rad_s", "Prefilter bandwidth w", "rad/s", 30.0, 5.0, 200.0,
      "Corner of the fourth-order prefilter (not in the paper).", step=1.0, group="Reference"),
    P("small_wave_frequency_rad_s", "Small wave frequency", "rad/s", 1.0, 0.5, 20.0,
      "Frequency of the 0.05 mm square and sine (paper: 1 and 2 rad/s).", step=0.1, group="Reference"),
    P("controller", "Controller", "", "linearising", choices=CONTROLLERS,
      description="linearising: eq. 2.21-2.30 on the EKF's estimate; lead-lag: the linear baseline on "
                  "the measured position (§3.5).", group="Controller"),
    P("pole_1_rad_s", "Pole η1", "rad/s", -60.0, -400.0, -1.0,
      "Closed-loop pole of the linearised chain (Table 3.1: -60).", step=1.0, group="Controller"),
    P("pole_2_rad_s", "Pole η2", "rad/s", -80.0, -400.0, -1.0,
      "Closed-loop pole (Table 3.1: -80).", step=1.0, group="Controller"),
    P("pole_3_rad_s", "Pole η3", "rad/s", -100.0, -400.0, -1.0,
      "Closed-loop pole (Table 3.1: -100).", step=1.0, group="Controller"),
    P("filter", "Filter", "", "continuous-discrete", choices=FILTERS,
      description="continuous-discrete: eq. 2.40-2.45; continuous-time: the paper's first filter "
                  "(App. G) with the sample variance R as noise density; continuous-time-Rdt: the same "
                  "with the consistent density R dt.", group="Kalman filter"),
    P("q_preset", "Q preset", "", "table_3.1", choices=Q_PRESETS,
      description="table_3.1: 0.025 diag(0, 1, 1) (simulations); eq_3.4: diag(1e-4, 0.75e-7, 1e-8) "
                  "(hardware); custom: the three sliders below.", group="Kalman filter"),
    P("q_position", "Q11 (custom)", "m²/s", 1e-12, 1e-12, 1e-2,
      "Process-noise density on position (used with q_preset=custom).", log=True, group="Kalman filter"),
    P("q_velocity", "Q22 (custom)", "m²/s³", 0.025, 1e-12, 1.0,
      "Process-noise density on velocity (used with q_preset=custom).", log=True, group="Kalman filter"),
    P("q_current", "Q33 (custom)", "A²/s", 0.025, 1e-12, 1.0,
      "Process-noise density on current (used with q_preset=custom).", log=True, group="Kalman filter"),
    P("initial_covariance", "P0 (× I)", "SI", 0.085, 1e-12, 1.0,
      "Initial covariance P0 = p0 I (Table 3.1: 0.085).", log=True, group="Kalman filter"),
    P("initial_position_error_mm", "Initial position error", "mm", round(PAPER_POSITION_ERROR_MM, 3),
      -5.0, 5.0, "Estimate minus plant at t = 0 (Table 3.1: 14.367 - 14.8 mm).", step=0.001,
      group="Kalman filter"),
    P("initial_current_error_percent", "Initial current error", "%", round(PAPER_CURRENT_ERROR_PERCENT, 2),
      -99.0, 100.0, "Estimate relative to the plant's current at t = 0 (Table 3.1: +5 %).", step=0.1,
      group="Kalman filter"),
    P("sensor_noise_mm", "Sensor noise σ", "mm", 1.0, 1e-4, 3.0,
      "Position sensor noise (Table 3.1: 1 mm in simulation; Table 3.2: 0.0034 mm on the hardware).",
      log=True, group="Plant"),
    P("plant_resistance_ohm", "True coil resistance", "Ω", 25.0, 15.0, 40.0,
      "Resistance of the simulated coil; the filter and controller keep Table 3.1's 25 Ω.  The paper's "
      "hardware filter used 27.6 Ω (App. G) and measured 25.3-26.7 Ω (App. H).", step=0.1, group="Plant"),
    P("plant_noise", "Plant process noise", "", "none", choices=("none", "matched"),
      description="none: the paper's simulated plant is noise free; matched: white noise with the "
                  "filter's own Q drives the plant.", group="Plant"),
    P("seed", "Random seed", "", 0, 0, 2**31 - 1, "Seed of this lab's noise.", integer=True, step=1,
      group="Run"),
    P("time_scale", "Time scale", "×", 0.3, 0.01, 2.0,
      "Simulated seconds per wall-clock second in the browser (1 = real time).", log=True, group="Run"),
)


def reference(values: dict, name: str | None = None) -> Reference:
    spec = dict(REFERENCES[name or values["reference"]])
    if spec["kind"] != "step" and spec["amplitude_m"] < 1e-4:
        spec["frequency_rad_s"] = values["small_wave_frequency_rad_s"]
    return Reference(**spec, base_m=GAP_M, smoothing=values["step_derivatives"],
                     prefilter_bandwidth_rad_s=values["prefilter_bandwidth_rad_s"])


def setup(values: dict, reference_name: str | None = None) -> MaglevSetup:
    """The experiment described by the parameter values."""
    Q = preset_q(values)
    current = TABLE_3_1.equilibrium_current_a(GAP_M)
    si = in_si(PARAMETERS, values)
    return MaglevSetup(
        true_plant=replace(TABLE_3_1, coil_resistance_ohm=values["plant_resistance_ohm"]),
        poles_rad_per_s=(values["pole_1_rad_s"], values["pole_2_rad_s"], values["pole_3_rad_s"]),
        controller=values["controller"], filter=values["filter"], filter_Q=Q,
        plant_Q=Q if values["plant_noise"] == "matched" else np.zeros((3, 3)),
        sensor_noise_m=si["sensor_noise_mm"],
        initial_state=(GAP_M, 0.0, current),
        initial_estimate=(GAP_M + si["initial_position_error_mm"], 0.0,
                          current * (1.0 + values["initial_current_error_percent"] / 100.0)),
        initial_covariance=values["initial_covariance"],
        reference=reference(values, reference_name))


def drawing_scale(values: dict) -> DrawingScale:
    """How the 3D view draws the gap: the reference's amplitude at 1 mm or more (life size at 1 mm and up)."""
    return DrawingScale(exaggeration_for(REFERENCES[values["reference"]]["amplitude_m"], 1e-3), GAP_M)


def within_3_sigma_percent(trace: dict, error: str, sigma: str) -> float:
    after = trace["time_s"] > SETTLE_S
    if not np.any(after):
        return float("nan")
    return float(np.mean(np.abs(trace[error][after]) <= 3.0 * trace[sigma][after]) * 100.0)


def rms_tracking_error_mm(trace: dict, start_s: float) -> float:
    after = trace["time_s"] >= start_s
    if not np.any(after):
        return float("nan")
    return float(np.sqrt(np.mean((trace["x_true_m"] - trace["reference_m"])[after] ** 2)) * 1e3)


CLAIMS = (
    *(Claim("paper 004 eq. 2.28", f"feedback gain k{j + 1} for poles −60, −80, −100 rad/s", f"{paper:,}".replace(",", " "),
            f"feedback_gain.{j}", (paper * 0.999, paper * 1.001), unit, duration_s=0.1)
      for j, (paper, unit) in enumerate(((480_000, "1/s³"), (18_800, "1/s²"), (240, "1/s")))),
    Claim("paper 004 §3.1.2, Fig. 3.2", "RMS tracking error after the 2 mm step (σ = 1 mm sensor noise)",
          "measured and estimated position hunt about the reference", "step_tracking_rms_error_mm", (None, 0.6),
          "mm", note="true gap against the reference, from 0.25 s after the step"),
    Claim("paper 004 §3.1.3, Fig. 3.7", "RMS tracking error, 1 mm sine at 10 rad/s (σ = 1 mm)", "“adequately tracks”",
          "sine_tracking_rms_error_mm", (None, 0.6), "mm"),
    Claim("paper 004 §3.1.2, Fig. 3.3", "position error inside the filter's ±3σ, 2 mm step",
          "inside", "position_error_within_3sigma_percent", (97, None), "%",
          note="share of samples after the first 0.25 s (a consistent filter: 99.7 %)"),
    Claim("paper 004 §3.1.2, Fig. 3.5", "velocity error inside the filter's ±3σ, 2 mm step",
          "inside", "velocity_error_within_3sigma_percent", (97, None), "%"),
)


class MaglevTracking(Exercise):
    name = "maglev_tracking"
    title = "Maglev ball: feedback linearisation with an EKF"
    worksheet = "maglev_tracking.md"
    parameters = PARAMETERS
    default_duration_s = 1.5
    min_duration_s = 1.1             # the 2 mm step comes at 0.75 s; its error is measured SETTLE_S after
    claims = CLAIMS
    download_label = "Record a lead-lag run (CSV)"
    key_readouts = ("Feedback gain k1", "Feedback gain k2", "Feedback gain k3", "Position error inside ±3σ",
                    "Velocity error inside ±3σ")
    charts = (
        Chart("Gap x1", "mm", (
            Series("measured", "x_measured_m", 1e3, "#c0c0c0"),
            Series("reference", "reference_m", 1e3, "#000000"),
            Series("true", "x_true_m", 1e3, "#1f77b4"),
            Series("estimated", "x_estimated_m", 1e3, "#d62728"))),
        Chart("Position error ±3σ", "mm", (
            Series("error", "position_error_m", 1e3, "#d62728"),), band=("zero", "x_sigma_m")),
        Chart("Velocity error ±3σ", "mm/s", (
            Series("error", "velocity_error_m_per_s", 1e3, "#9467bd"),),
            band=("zero", "velocity_sigma_m_per_s")),
        Chart("Coil current", "A", (
            Series("true", "current_true_a", 1.0, "#1f77b4"),
            Series("estimated", "current_estimated_a", 1.0, "#2ca02c"))),
        Chart("Coil voltage", "V", (Series("u", "coil_voltage_v", 1.0, "#ff7f0e"),)),
    )

    def model(self, values: dict) -> dict:
        s = setup(values)
        F = np.asarray(TABLE_3_1.linear_model().A)
        return {"states": ["x1 gap [m]", "x2 velocity [m/s]", "x3 current [A]"], "inputs": ["u coil [V]"],
                "outputs": ["x1 [m]"], "sample_time_s": T, "plant": "eq. 2.10, Table 3.1",
                "constants": {"mass_kg": TABLE_3_1.mass_kg, "coil_inductance_h": TABLE_3_1.coil_inductance_h,
                              "coil_resistance_ohm": TABLE_3_1.coil_resistance_ohm,
                              "force_constant_n_m2_per_a2": TABLE_3_1.force_constant_n_m2_per_a2},
                "jacobian_at_14_8_mm": F.tolist(), "feedback_gain": s.gain.tolist(),
                "Q": s.filter_Q.tolist(), "R": s.sensor_noise_m**2, "P0": (s.initial_covariance * np.eye(3)).tolist()}

    def open_loops(self, values: dict) -> dict:
        """The running controller, linearised at the equilibrium at 14.8 mm."""
        name = "lead-lag" if values["controller"] == "lead-lag" else "linearising control + EKF"
        return {name: loop_at_plant_input(setup(values))}

    def analyse(self, values: dict) -> Analysis:
        s = setup(values)
        k = s.gain
        plant = TABLE_3_1.linear_model()
        lead_lag_loop = control.feedback(plant, LEAD_LAG.transfer_function(), sign=1)
        current = TABLE_3_1.equilibrium_current_a(GAP_M)
        readouts = [
            ("Feedback gain k1", k[0], "1/s³"), ("Feedback gain k2", k[1], "1/s²"),
            ("Feedback gain k3", k[2], "1/s"),
            ("Equilibrium current at 14.8 mm (eq. 2.14)", current, "A"),
            ("Equilibrium voltage at 14.8 mm", TABLE_3_1.equilibrium_voltage_v(GAP_M), "V"),
            ("Open-loop unstable pole (linearised at 14.8 mm)", np.sqrt(2 * TABLE_3_1.gravity_m_per_s2 / GAP_M), "rad/s"),
            ("Decoupling gain at 14.8 mm (eq. 2.17, inverted)", decoupling_gain_v_per_m_s3(GAP_M, current) * 1e3,
             "mV/(m/s³)"),
        ]
        chain = brunovsky_chain()
        closed_chain = control.ss(chain.A - chain.B @ k[None, :], chain.B * k[0], chain.C, 0.0)
        t = np.linspace(0.0, 0.5, 501)
        _, step = control.step_response(closed_chain, T=t)
        w = values["prefilter_bandwidth_rad_s"]
        tf_s = control.tf("s")
        _, prefiltered = control.step_response(w**4 / (tf_s + w) ** 4 * control.ss2tf(closed_chain), T=t)
        currents = np.linspace(0.05, 2.0, 196)
        voltages = np.array([linearising_control(np.array([GAP_M, 0.0, i]), np.array([GAP_M, 0, 0, 0]),
                                                 k, TABLE_3_1.constants())[0] for i in currents])
        plots = [
            Plot("Linearised loop (eq. 2.29): response to a 2 mm reference step", "time [s]", "gap change [mm]",
                 t, (("step, zeroed derivatives", 2.0 * np.asarray(step).ravel(), "#1f77b4"),
                     ("through the prefilter", 2.0 * np.asarray(prefiltered).ravel(), "#d62728"))),
            Plot("Voltage the controller asks for at 14.8 mm vs estimated current (x3 -> 0 is singular)",
                 "estimated current x̂3 [A]", "coil voltage u [V]", currents,
                 (("u(x̂) by eq. 2.23", voltages, "#ff7f0e"),)),
        ]
        poles = {"open-loop plant (linearised, 14.8 mm)": np.linalg.eigvals(np.asarray(plant.A)),
                 "feedback-linearised loop (eq. 2.29)": np.array(s.poles_rad_per_s, dtype=complex),
                 "lead-lag loop (linearised)": lead_lag_loop.poles()}
        notes = [(f"Singularity guard: estimates with x̂1 < 1 mm or x̂3 < {GUARD_CURRENT_A * 1e3:.0f} mA are "
                 "clamped before eq. 2.23; the voltage grows as 1/x̂3 towards that edge.")]
        return Analysis(readouts, poles, notes, plots)

    def mode_matrices(self, values: dict) -> dict[str, tuple]:
        """The lead-lag loop by its states: the ball's gap and velocity and the coil current
        (paper 004 eq. 2.10, linearised at 14.8 mm, eq. 2.13-2.14) and the compensator's three
        states, pooled (participation summed over a block does not depend on the block's
        realisation).  The feedback-linearised loop's poles are the design's −η roots of the
        linear error dynamics (eq. 2.29), not eigenvalues of a physical state matrix: they keep
        their generic kind."""
        loop = control.feedback(TABLE_3_1.linear_model(), LEAD_LAG.transfer_function(), sign=1)
        states = [("x₁ gap [m]", "ball position/velocity (levitation mode)"),
                  ("x₂ velocity [m/s]", "ball position/velocity (levitation mode)"),
                  ("x₃ coil current [A]", "coil current")]
        states += [(f"lead-lag state {k + 1} [V]", "lead-lag compensator") for k in range(loop.nstates - 3)]
        return {"lead-lag loop (linearised)": (np.asarray(loop.A), states, None)}

    def pole_categories(self, values: dict) -> dict[str, PoleCategory]:
        return {"open-loop plant (linearised, 14.8 mm)": PoleCategory.PLANT,
                "feedback-linearised loop (eq. 2.29)": PoleCategory.CLOSED_LOOP,
                "lead-lag loop (linearised)": PoleCategory.CLOSED_LOOP}

    def mode_names(self, values: dict, poles: dict[str, np.ndarray]) -> dict[str, list[str | None]]:
        """The linearised plant's poles by name (the loops' poles keep their generic kind)."""
        name = "open-loop plant (linearised, 14.8 mm)"
        return {name: magnet_plant_names(poles[name], TABLE_3_1.linear_model().A, "ball", MAGLEV_LAGS)}

    def simulation(self, values: dict) -> MaglevSimulation:
        return MaglevSimulation(setup(values), seed=int(values["seed"]))

    def scene(self, values: dict) -> MaglevScene:
        """The ball at its true gap, the estimate as its outline; life size, or the 0.05 mm
        references magnified to about 1 mm."""
        return MaglevScene(values, Columns(ball="x_true_m", ball_label="ball", current="current_true_a",
                                           ghost="x_estimated_m", guarded="guarded",
                                           velocity="velocity_true_m_per_s"), drawing_scale)

    def live_readouts(self, trace: dict[str, np.ndarray]) -> list[tuple[str, float, str]]:
        inside_x = np.mean(np.abs(trace["position_error_m"]) <= 3 * trace["x_sigma_m"]) * 100
        inside_v = np.mean(np.abs(trace["velocity_error_m_per_s"]) <= 3 * trace["velocity_sigma_m_per_s"]) * 100
        return [("RMS tracking error", float(np.sqrt(np.mean((trace["x_true_m"] - trace["reference_m"]) ** 2)))
                 * 1e3, "mm"),
                ("Position error inside ±3σ", float(inside_x), "%"),
                ("Velocity error inside ±3σ", float(inside_v), "%"),
                ("Guarded controller steps", float(np.sum(trace["guarded"])), "")]

    def metrics(self, values: dict, duration_s: float) -> dict:
        seed = int(values["seed"])
        runs = {}
        for name in ("step_2mm", "sine_1mm", values["reference"]):
            if name not in runs:
                sim = MaglevSimulation(setup(values, name), seed=seed)
                runs[name] = (sim, sim.run(duration_s))
        step_sim, step = runs["step_2mm"]
        sine_sim, sine = runs["sine_1mm"]
        chosen_sim, chosen = runs[values["reference"]]
        step_time = step_sim.setup.reference.step_time_s
        return {
            "feedback_gain": setup(values).gain.tolist(),
            "step_tracking_rms_error_mm": rms_tracking_error_mm(step, step_time + SETTLE_S),
            "sine_tracking_rms_error_mm": rms_tracking_error_mm(sine, 2 * SETTLE_S),
            "position_error_within_3sigma_percent": within_3_sigma_percent(chosen, "position_error_m",
                                                                           "x_sigma_m"),
            "velocity_error_within_3sigma_percent": within_3_sigma_percent(chosen, "velocity_error_m_per_s",
                                                                           "velocity_sigma_m_per_s"),
            "within_3sigma_window_s": [SETTLE_S, float(chosen["time_s"][-1]) if chosen["time_s"].size else 0.0],
            "estimation_rms_position_error_mm": float(np.sqrt(np.mean(chosen["position_error_m"] ** 2)) * 1e3),
            "peak_coil_voltage_v": float(np.max(np.abs(chosen["coil_voltage_v"]))),
            "guarded_controller_steps": int(np.sum(chosen["guarded"])),
            "status_step": step_sim.status_message() or "ok",
            "status_sine": sine_sim.status_message() or "ok",
            "status": chosen_sim.status_message() or "ok",
            "duration_s": float(chosen["time_s"][-1] + T) if chosen["time_s"].size else 0.0,
        }

    def report_figures(self, values: dict) -> list:
        """Figs. 3.2-3.5: the 2 mm step tracked, and the estimation errors inside their ±3σ bounds."""
        from lab_modules.exercises._figures import scope_figure
        return [scope_figure(self, [("", values)], self.default_duration_s, "2 mm step: gap and estimation "
                             "errors with ±3σ bounds", charts=("Gap x1", "Position error ±3σ", "Velocity error ±3σ"))]

    def download(self, values: dict) -> tuple[str, bytes]:
        """A recording for ``maglev_tuning`` (§3.5): 1 s at rest on the positioning
        tool, then 5 s held at 14.8 mm by the lead-lag controller, with this
        exercise's sensor noise and seed (the shipped recording's settings otherwise)."""
        noise_mm, seed = values["sensor_noise_mm"], int(values["seed"])
        try:
            run = record_lead_lag_run(duration_s=6.0, still_s=1.0, sensor_noise_m=noise_mm * 1e-3, seed=seed)
        except RuntimeError as stopped:
            raise ParameterError(f"no recording: with sensor_noise_mm = {noise_mm:g} the lead-lag loop lost "
                                 f"the ball ({stopped}); record with less noise, e.g. the hardware's "
                                 "0.0034 mm") from None
        return f"maglev_leadlag_noise_{noise_mm:g}mm_seed_{seed}.csv", to_csv(run).encode("utf-8")


EXERCISE = MaglevTracking()
