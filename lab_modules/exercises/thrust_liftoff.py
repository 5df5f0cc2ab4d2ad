"""Exercise ``thrust_liftoff``: filter before you differentiate.

Paper 003 (Jiang, Su, Wang), a 281 kg axial (thrust) magnetic bearing under
an industrial PID (Table 1: Kp = 3, Ki = 10, Kd = 0.022) with a Kalman filter
in front of it (Fig. 4, 7).  The collar lifts off the touchdown bearing at
X0 = −0.75 mm and is held at the centre.  The paper reports a calmer lift-off
(hardware, Fig. 10: overshoot about 64 % with the raw measurement, about 14 %
with the filter) and 3-4 times better steady-state accuracy (Fig. 11).

The lab's reading (each choice is stated where it is made and in the worksheet):

* PID units: error in mm, command in A (Kp = 3 A/mm, Ki = 10 A/(mm s),
  Kd = 0.022 A s/mm) -- the only reading with a stable loop: the net stiffness
  k_i Kp − |k_x| = 5143 · 3000 − 4.594e6 = 10.8 N/µm > 0; per metre it would
  be −4.6 N/µm.  Kp < |k_x|/k_i = 0.893 A/mm is unstable.
* The D term is the unfiltered backward difference of the fed-back position
  (the paper shows no derivative filter); ``derivative_filter_ms`` adds one.
* The filter is a linear KF on the fixed linearisation (``estimators.thrust_kalman``),
  Q = 2.64e6 N² read from P0, R = σ_v²; its input is the measured coil current,
  so the current loop G(s) is outside its model.  The paper's name for it, EKF, is offered
  as a choice: eq. 2 re-linearised at the estimate every sample (``estimators.thrust_ekf``),
  optionally with the touchdown stop in its model; compared on the nonlinear plant
  (``_thrust_liftoff_filters``).
* Sensor noise σ_v = 5 µm (not in the paper); no plant force disturbance by default.

The hardware's 64 % vs 14 % cannot be reproduced from the published data: with
the printed gains the noise-free lift-off overshoots 4.4 % whatever the feedback
source (separation principle), and the hardware's noise, sensor lag and
amplifier are not given.  The "harsh sensor" claim shows the mechanism
(D-term noise saturating the amplifier) as an illustration.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from lab_modules import analysis
from lab_modules.claims import Claim
from lab_modules.estimators.thrust_kalman import PAPER_Q_N2, H
from lab_modules.exercises import POLE_MAP, SCOPE, Analysis, Chart, Exercise, Plot, PoleCategory, Series
from lab_modules.exercises._common import pairs
from lab_modules.exercises._thrust_liftoff_filters import (
    COLOURS,
    FILTER_CLAIMS,
    LABELS,
    comparison,
    noise_free_errors,
)
from lab_modules.exercises._thrust_liftoff_labels import liftoff_gap_evidence, median_standard_error
from lab_modules.loops.thrust_liftoff_linear import linear_loop, loop_at_plant_input
from lab_modules.loops.thrust_liftoff_loop import ThrustSetup, ThrustSimulation, liftoff_figures
from lab_modules.memo import remembered
from lab_modules.parameters import Parameter, in_si
from lab_modules.plants.thrust_bearing import TABLE_1
from lab_modules.scenes.thrust_bearing import ThrustBearingScene

T = TABLE_1.sample_time_s
MM = 1e-3
#: Steady-state statistics are taken from this time on: the integral's slow mode
#: has decayed below 0.3 µm by then (noise-free lift-off at the defaults).
STEADY_FROM_S = 1.0
LIFTOFF_RUN_S = 0.6            # the noise-free lift-off runs (settled within 2 % by 0.25 s)
GAIN_HISTORY_MS = 5.0          # Kalman gain and P plotted over the first milliseconds
FILTER_ERROR_PLOT_S = 0.04     # the filters' lift-off errors plotted over the first 40 ms
SOURCES = ("measured", "estimated")
FILTER_MODELS = ("Taylor (eq. 9-11)", "exact ZOH", "EKF (eq. 2 re-linearised)")

P = Parameter
PARAMETERS = (
    P("sensor_noise_um", "Sensor noise σ_v", "µm", 5.0, 0.0, 50.0,
      "Standard deviation of the eddy-current sensor's white noise (not in the paper: 5 µm).",
      step=0.5, group="Noise"),
    P("noise_correlation_ms", "Sensor noise correlation time", "ms", 0.0, 0.0, 5.0,
      "0 = white noise (the filter's assumption); > 0: first-order coloured noise of the same σ_v "
      "(§3.2: the hardware's noise is not white).", step=0.05, group="Noise"),
    P("force_noise_n", "Plant force disturbance σ_f", "N", 0.0, 0.0, 5000.0,
      "Standard deviation of a white force on the collar, per 0.1 ms sample (eq. 3's f_dis; default off).",
      step=10.0, group="Noise"),
    P("filter_q_n2", "Filter Q (force)", "N²", round(PAPER_Q_N2, -3), 1e2, 1e10,
      "Process-noise variance of f_dis the filter assumes per sample (eq. 15); default read from P0.",
      log=True, group="Kalman filter"),
    P("filter_r_factor", "Filter R / σ_v²", "×", 1.0, 0.01, 100.0,
      "Measurement variance the filter assumes, relative to the sensor's σ_v² (1 = matched).",
      log=True, group="Kalman filter"),
    P("filter_model", "Filter model", "", FILTER_MODELS[0], choices=FILTER_MODELS,
      description="The filter's Φ, B_d: the paper's second-order Taylor series (eq. 9-11), the plant's exact "
                  "ZOH matrices (the noise-free lift-offs differ by the same 0.36 µm: the stop does it), or an "
                  "EKF: the Taylor series of eq. 2 at its own estimate every sample (for the nonlinear plant).",
      group="Kalman filter"),
    P("filter_stop", "Touchdown stop in the filter", "", "no", choices=("no", "yes"),
      description="yes: the filter's prediction stops at the touchdown bearing as the collar does (x̂ clamped "
                  "at ±0.75 mm, v̂ set to 0 when pushed into it).", group="Kalman filter"),
    P("feedback", "Feedback source", "", "measured", choices=SOURCES,
      description="Position the PID acts on: the raw measurement z (Fig. 6) or the filter's estimate x̂ (Fig. 7).",
      group="Controller"),
    P("derivative_source", "D term from", "", "difference", choices=("difference", "velocity"),
      description="With estimated feedback: backward difference of x̂, or the filter's velocity v̂.",
      group="Controller"),
    P("kp_a_per_mm", "Proportional gain Kp", "A/mm", 3.0, 0.1, 10.0,
      "Table 1: 3 (read as A/mm; below 0.893 A/mm the loop is unstable).", step=0.01, group="Controller"),
    P("ki_a_per_mm_s", "Integral gain Ki", "A/(mm·s)", 10.0, 0.0, 100.0,
      "Table 1: 10.", step=0.5, group="Controller"),
    P("kd_a_s_per_mm", "Derivative gain Kd", "A·s/mm", 0.022, 0.0, 0.1,
      "Table 1: 0.022.", step=0.001, group="Controller"),
    P("derivative_filter_ms", "Derivative filter τ_d", "ms", 0.0, 0.0, 10.0,
      "First-order filter on the D term (not in the paper: 0 = unfiltered backward difference).",
      step=0.05, group="Controller"),
    P("current_limit_a", "Current limit", "A", TABLE_1.current_limit_a, 0.5, 20.0,
      "Limit of the current command (Table 1: 10 A); the integral stops while it is reached.",
      step=0.5, group="Controller"),
    P("start_position_mm", "Start position", "mm", -0.75, -0.75, 0.0,
      "Where the collar starts, at rest (§3: X0 = −0.75 mm, on the touchdown bearing).",
      step=0.01, group="Lift-off"),
    P("relaunch_s", "Lift off again every", "s", 1.0, 0.0, 10.0,
      "The browser's run starts a new lift-off this often (0 = once).", step=0.1, group="Lift-off"),
    P("current_loop", "Current loop G(s)", "", "on", choices=("on", "off"),
      description="on: the identified G(s) of §3.1 between command and coil current; off: ideal amplifier.",
      group="Plant"),
    P("force_law", "Plant force law", "", "linear", choices=("linear", "nonlinear"),
      description="True plant: eq. 4-5 (linear, as the paper's simulation) or eq. 2 (nonlinear).",
      group="Plant"),
    P("orientation", "Machine axis", "", "horizontal", choices=("horizontal", "vertical"),
      description="horizontal: the paper's machine, no gravity on the axis; vertical: 281 kg · g on it.",
      group="Plant"),
    P("seeds", "Seeds for the statistics", "", 3, 1, 64,
      "Headless metrics: number of noise realisations averaged (mean) or summarised (median).",
      integer=True, step=1, group="Run"),
    P("seed", "Random seed", "", 0, 0, 2**31 - 1, "Seed of this lab's noise.", integer=True, step=1,
      group="Run"),
    P("time_scale", "Time scale", "×", 0.1, 0.001, 1.0,
      "Simulated seconds per wall-clock second in the browser (1 = real time).", log=True, group="Run"),
)


def setup(values: dict, **changes) -> ThrustSetup:
    """The experiment described by the parameter values (the paper's mm read as SI)."""
    si = in_si(PARAMETERS, values)
    s = ThrustSetup(
        proportional_a_per_m=si["kp_a_per_mm"],
        integral_a_per_m_s=si["ki_a_per_mm_s"],
        derivative_a_s_per_m=si["kd_a_s_per_mm"],
        derivative_filter_s=si["derivative_filter_ms"],
        current_limit_a=values["current_limit_a"],
        use_estimate=values["feedback"] == "estimated",
        derivative_from_velocity=values["derivative_source"] == "velocity",
        current_loop=values["current_loop"] == "on",
        nonlinear=values["force_law"] == "nonlinear",
        vertical=values["orientation"] == "vertical",
        sensor_noise_m=si["sensor_noise_um"],
        sensor_noise_correlation_s=si["noise_correlation_ms"],
        force_noise_n=values["force_noise_n"],
        filter_q_n2=values["filter_q_n2"],
        filter_r_factor=values["filter_r_factor"],
        start_position_m=si["start_position_mm"],
        filter_exact_model=values["filter_model"] == FILTER_MODELS[1],
        filter_extended=values["filter_model"] == FILTER_MODELS[2],
        filter_knows_stop=values["filter_stop"] == "yes")
    return replace(s, **changes)


def instability_note(s: ThrustSetup) -> str:
    """'' for a stable linear loop; otherwise one sentence why it is not."""
    loop = linear_loop(s)
    if loop.stable():
        return ""
    b = s.bearing
    net = (b.current_stiffness_n_per_a * s.proportional_a_per_m - b.negative_stiffness_n_per_m) * 1e-6
    critical = b.critical_proportional_gain_a_per_m * MM
    if net < 0:
        return (f"The loop is unstable: Kp = {s.proportional_a_per_m * MM:.3g} A/mm is below "
                f"|k_x|/k_i = {critical:.3f} A/mm (net stiffness k_i·Kp − |k_x| = {net:.2f} N/µm < 0).")
    return (f"The loop is unstable: a closed-loop pole lies at |z| = {np.max(np.abs(loop.poles())):.4f} > 1 "
            "(too little damping for this Kp, Ki and current loop).")


def one_line(matrix, digits: int) -> str:
    """A matrix as one line of text, rows in brackets."""
    return np.array2string(np.asarray(matrix), precision=digits, separator=", ").replace("\n", "")


def to_s(poles_z) -> np.ndarray:
    """Continuous equivalents s = ln(z)/T of the poles; poles at z = 0 (pure one-sample
    delays of the difference and the derivative state) have none and are left out."""
    poles_z = np.asarray(poles_z, dtype=complex)
    return analysis.z_to_s(poles_z[np.abs(poles_z) > 1e-12], T)


def pole_damping(poles_z) -> tuple[float, float]:
    """Largest |z| and the smallest damping ratio of the continuous equivalents."""
    s = analysis.z_to_s(poles_z, T)
    damping = -s.real / np.maximum(np.abs(s), 1e-300)
    return float(np.max(np.abs(poles_z))), float(np.min(damping))


def liftoff(values: dict, source: str, duration_s: float = LIFTOFF_RUN_S, **changes) -> tuple[dict, str]:
    """The noise-free lift-off (no noise draws; the filter keeps its R = factor · σ_v²)."""
    sim = ThrustSimulation(setup(values, use_estimate=source == "estimated", noise_on=False, **changes))
    return sim.run(duration_s), sim.status_message() or "ok"


@remembered()
def liftoff_runs(values: dict) -> dict[str, tuple[dict, str]]:
    """``liftoff`` of both feedback sources."""
    return {src: liftoff(values, src) for src in SOURCES}


@remembered()
def filter_errors(values: dict) -> dict[str, dict]:
    """``noise_free_errors`` of the four filters on the nonlinear plant, estimate fed back."""
    return noise_free_errors(setup(values))


def steady_window_start_s(duration_s: float) -> float:
    """Start of the steady-state window: ``STEADY_FROM_S``, or half of a shorter run."""
    return min(STEADY_FROM_S, 0.5 * duration_s)


def steady_std(trace: dict, column: str, duration_s: float) -> float:
    """Standard deviation of a column from ``steady_window_start_s`` on (NaN if the run stopped before)."""
    samples = trace[column][trace["time_s"] >= steady_window_start_s(duration_s)]
    return float(np.std(samples)) if samples.size > 10 else float("nan")


class ThrustLiftoff(Exercise):
    name = "thrust_liftoff"
    title = "Thrust bearing: filter, then differentiate"
    worksheet = "thrust_liftoff.md"
    parameters = PARAMETERS
    default_duration_s = 2.0
    min_duration_s = 0.3             # the lift-off settles within about 0.21 s (its settling-time metric)
    key_readouts = ("Net stiffness of the loop", "Accuracy gain std z / std x̂",
                    "Steady std of true x, raw PID", "Steady std of true x, filter-PID",
                    "Time at the current limit")
    charts = (
        Chart("Lift-off: collar position", "µm", (
            Series("measured z", "x_measured_m", 1e6, "#b0b0b0"),
            Series("true x", "x_true_m", 1e6, "#1f77b4"),
            Series("estimate x̂", "x_estimated_m", 1e6, "#d62728"),
            Series("touchdown", "touchdown_upper_m", 1e6, "#000000"),
            Series("touchdown ", "touchdown_lower_m", 1e6, "#000000")),
            band=("x_estimated_m", "x_sigma_m")),
        Chart("Estimation error x̂ − x, ±3σ", "µm", (
            Series("error", "estimation_error_m", 1e6, "#d62728"),), band=("zero", "x_sigma_m")),
        Chart("Coil current", "A", (
            Series("command", "current_command_a", 1.0, "#ff7f0e"),
            Series("coil current", "current_a", 1.0, "#2ca02c"),
            Series("limit", "current_limit_a", 1.0, "#000000"),
            Series("limit ", "current_limit_negative_a", 1.0, "#000000"))),
    )
    claims = (
        Claim("paper 003 §3.1, Fig. 8", "noise-free lift-off overshoot of x, raw-measurement PID",
              "Fig. 8: visibly larger than with the filter (no number printed)",
              "liftoff_overshoot_percent_measured_feedback", (4.1, 4.7), "%",
              "Noise draws off, linear plant, G(s) on; overshoot of the true position relative to 0.75 mm.",
              deviation=True),
        Claim("paper 003 §3.1, Fig. 8", "noise-free lift-off overshoot of x, filter-PID",
              "Fig. 8: smaller and smoother than without the filter",
              "liftoff_overshoot_percent_estimated_feedback", (4.1, 4.7), "%",
              "Without noise the estimate equals the state (separation principle), so both lift-offs coincide.",
              deviation=True),
        Claim("paper 003 §3.2", "largest difference between the two noise-free lift-offs",
              "settling times \"basically the same\"", "liftoff_max_difference_um", (None, 1.5), "µm",
              "The touchdown stop, which the filter does not model, holds the collar while the filter's "
              "estimate moves (rows below: the Taylor model accounts for 0.0006 µm)."),
        Claim("paper 003 §3.2 (lab evidence)", "that difference with the filter on the exact ZOH matrices",
              "not printed", "liftoff_gap.exact_filter_on_stop_um", (0.30, 0.42), "µm",
              "Unchanged from the Taylor filter's 0.36 µm: the Taylor model is not the cause."),
        Claim("paper 003 §3.2 (lab evidence)", "that difference off the stop, Taylor filter", "not printed",
              "liftoff_gap.taylor_filter_off_stop_um", (None, 0.002), "µm",
              "The collar starts free at X0 (stop out of reach): only eq. 9-11 against e^{AT} is left."),
        Claim("paper 003 §3.2 (lab evidence)", "that difference off the stop, exact filter", "not printed",
              "liftoff_gap.exact_filter_off_stop_um", (None, 1e-6), "µm",
              "Nothing the filter does not know: the separation principle holds to rounding."),
        Claim("paper 003 §3.1, Fig. 8", "peak time of the noise-free lift-off", "not printed",
              "liftoff_peak_time_ms", (47.0, 53.0), "ms", "Time of the largest x, raw-measurement PID."),
        Claim("paper 003 §3.2, Fig. 10", "2 % settling time of the lift-off", "about the same for both",
              "settling_time_2pct_s", (0.19, 0.23), "s", "Last time |x| > 15 µm, raw-measurement PID."),
        Claim("paper 003 §3.2, Fig. 11", "steady-state accuracy gain (std z under PID / std x̂ under filter-PID)",
              "3-4×", "steady_std_ratio", (2.5, 3.3), "×",
              "Below the paper's 3-4× at the lab's σ_v = 5 µm (mean of 3 seeds, 1 s to 2 s): the gain grows with "
              "the sensor noise against the fixed Q, and the hardware's noise is not given (3-4× at 10 µm).",
              deviation=True),
        Claim("paper 003 §3.2, Fig. 11", "steady-state accuracy gain at σ_v = 10 µm", "3-4×",
              "steady_std_ratio", (3.0, 4.0), "×", "Mean of 3 seeds; the gain grows with the sensor noise.",
              settings={"sensor_noise_um": 10.0}),
        Claim("paper 003 §0 (motivation)", "current-noise reduction (std command PID / filter-PID)",
              "not printed (the D term's noise is the paper's motivation)", "current_noise_ratio",
              (7.6, 11.6), "×", "σ_v = 5 µm, mean of 3 seeds."),
        Claim("paper 003 §2.4", "estimation error inside the filter's ±3σ", "not printed",
              "estimate_within_3sigma_percent", (99.0, None), "%",
              "Filter-PID, steady state: the filter's P covers its actual error."),
        Claim("paper 003 §3.2, Fig. 10", "harsh sensor: median lift-off overshoot of x, raw PID",
              "about 64 % (hardware)", "noisy_liftoff_overshoot_median_percent_measured_feedback", (50.0, 66.0),
              "%", "Illustration, not a reproduction: σ_v = 35 µm makes the D term's noise saturate the "
              "10 A limit; the hardware's noise is not published. 40 seeds: median 58 %, its standard error "
              "2.0 points, so each edge of the band is 4 standard errors away.", deviation=True,
              settings={"sensor_noise_um": 35.0, "seeds": 40}),
        Claim("lab (statistics of the row above)", "harsh sensor: standard error of that median, 40 seeds",
              "not printed", "noisy_liftoff_overshoot_median_se_percent_measured_feedback", (None, 2.6), "%",
              "√(π/2) s/√n; seeds spread ±10 points: 12 seeds would leave the median ±3.6 points",
              settings={"sensor_noise_um": 35.0, "seeds": 40}),
        Claim("paper 003 §3.2, Fig. 10", "harsh sensor: median lift-off overshoot of x, filter-PID",
              "about 14 % (hardware)", "noisy_liftoff_overshoot_median_percent_estimated_feedback", (None, 8.0),
              "%", "Illustration at σ_v = 35 µm, 40 seeds (see above).", deviation=True,
              settings={"sensor_noise_um": 35.0, "seeds": 40}),
    ) + FILTER_CLAIMS

    def model(self, values: dict) -> dict:
        s = setup(values)
        b = s.bearing
        Phi, B_d, Q_d = s.design.matrices
        Phi_exact, B_exact, _ = b.exact_discretisation()
        return {"states": ["x [m]", "v [m/s]"], "inputs": ["measured coil current i_x [A]"],
                "outputs": ["z [m]"], "sample_time_s": T,
                "A": Phi.tolist(), "B": B_d.tolist(), "C": [[1.0, 0.0]], "Q": Q_d.tolist(),
                "R": [[s.design.measurement_variance_m2]], "Q_force_n2": s.filter_q_n2,
                "A_exact": Phi_exact.tolist(), "B_exact": B_exact.tolist(),
                "bias_current_a": b.bias_current_a, "force_constant_n_m2_per_a2": b.force_constant_n_m2_per_a2,
                "pid_units": "e [mm] -> i_c [A]: Kp [A/mm], Ki [A/(mm s)], Kd [A s/mm]"}

    def open_loops(self, values: dict) -> dict:
        """The lift-off loop on the linear plant (eq. 5), broken at the current command."""
        return {f"PID, {values['feedback']} x": loop_at_plant_input(setup(values))}

    def analyse_panel(self, values: dict, panel: str) -> Analysis:
        """The Scope: the linear figures (Lyapunov noise, Riccati gains, discretisation); the Pole map:
        the loops' and the filter's poles; the Analysis tab: the noise-free lift-offs, the filter's
        gain history and the current noise over the sensor's."""
        if panel == SCOPE:
            return self._linear_figures(values)
        if panel == POLE_MAP:
            return Analysis([], self._poles(values), [])
        s = setup(values)
        errors = filter_errors(values)
        readouts = [(f"Noise-free lift-off, nonlinear plant: largest |x̂ − x|, {LABELS[name]}",
                     float(np.max(np.abs(run["error_m"]))) * 1e6, "µm") for name, run in errors.items()]
        notes = [f"{LABELS[name]}: {run['status']}" for name, run in errors.items() if run["status"]]
        plots = [self._liftoff_plot(liftoff_runs(values)), self._filter_error_plot(errors), self._gain_plot(s.design),
                 self._current_noise_plot(s)]
        return Analysis(readouts, {}, notes, plots)

    @staticmethod
    def _linear_figures(values: dict) -> Analysis:
        """Readouts and notes of the linear analysis (poles, Lyapunov noise, the filter's steady state)
        and of the noise-free lift-offs."""
        s = setup(values)
        b = s.bearing
        gain, _, P_corr = s.design.steady_state
        std = {src: linear_loop(replace(s, use_estimate=src == "estimated")).output_std(s.sensor_noise_m,
                                                                                         s.force_noise_n)
               for src in SOURCES}
        radius, damping = pole_damping(s.design.error_poles())
        regulator = linear_loop(replace(s, use_estimate=False), with_filter=False)
        Phi, B_d, _ = b.taylor_discretisation()
        Phi_e, B_e, _ = b.exact_discretisation()
        net = (b.current_stiffness_n_per_a * s.proportional_a_per_m - b.negative_stiffness_n_per_m) * 1e-6
        d_noise = s.derivative_a_s_per_m * np.sqrt(2.0) * s.sensor_noise_m / T
        readouts = [
            ("Bias current i0", b.bias_current_a, "A"),
            ("Force constant k_f", b.force_constant_n_m2_per_a2 * 1e3, "mN·m²/A²"),
            ("Open-loop unstable pole", b.open_loop_pole_rad_per_s, "rad/s"),
            ("Net stiffness of the loop", net, "N/µm"),
            ("Smallest stable Kp", b.critical_proportional_gain_a_per_m * MM, "A/mm"),
            ("Largest closed-loop pole radius in z (with G(s))", float(np.max(np.abs(regulator.poles()))), ""),
            ("Steady std of z, raw PID", std["measured"]["x_measured_m"] * 1e6, "µm"),
            ("Steady std of x̂, filter-PID", std["estimated"]["x_estimated_m"] * 1e6, "µm"),
            ("Accuracy gain std z / std x̂", std["measured"]["x_measured_m"]
             / max(std["estimated"]["x_estimated_m"], 1e-300), "×"),
            ("Steady std of true x, raw PID", std["measured"]["x_true_m"] * 1e6, "µm"),
            ("Steady std of true x, filter-PID", std["estimated"]["x_true_m"] * 1e6, "µm"),
            ("Current noise: command, raw PID", std["measured"]["current_command_a"], "A"),
            ("Current noise: command, filter-PID", std["estimated"]["current_command_a"], "A"),
            ("Current noise: D term alone, raw PID", d_noise, "A"),
            ("Filter: Kalman gain K∞ (x ← z)", gain[0], ""),
            ("Filter: Kalman gain K∞ (v ← z)", gain[1], "1/s"),
            ("Filter: σ of x at steady state", np.sqrt(max(P_corr[0, 0], 0.0)) * 1e6, "µm"),
            ("Filter: error pole radius in z", radius, ""),
            ("Filter: error pole damping", damping, ""),
            ("Filter: largest error of the Taylor Φ against the exact one", float(np.max(np.abs(Phi - Phi_e))), ""),
        ]
        runs = liftoff_runs(values)
        figures = {src: liftoff_figures(runs[src][0], s.start_position_m) for src in SOURCES}
        lifted = [
            ("Noise-free overshoot, raw PID", figures["measured"]["overshoot_percent"], "%"),
            ("Noise-free overshoot, filter-PID", figures["estimated"]["overshoot_percent"], "%"),
            ("Noise-free peak time", figures["measured"]["peak_time_s"] * 1e3, "ms"),
            ("Noise-free 2 % settling time", figures["measured"]["settling_time_s"], "s"),
        ]
        notes = [
            ("Discretisation at T = 0.1 ms, Taylor (eq. 9-11) vs exact: "
             f"Φ (Taylor) = {one_line(Phi, 9)}, e^(AT) = {one_line(Phi_e, 9)}; "
             f"B_d (Taylor) = {one_line(B_d, 7)}, exact = {one_line(B_e, 7)} [m/A, m/(A s)]."),
            (("The filter is an EKF: eq. 2's Taylor series at its own estimate every sample, P propagated with "
              "that Jacobian; at the centre it equals the linear filter, so the figures above are both filters'; "
              if s.filter_extended else
              "The filter is a linear Kalman filter on the fixed linearisation (Φ, B_d, G_d constant); ")
             + "eq. 17 is implemented in its standard form (correct the prediction, not the previous estimate)."),
        ]
        note = instability_note(s)
        if note:
            notes.insert(0, note)
        return Analysis(readouts[:6] + lifted + readouts[6:], {}, notes)

    @staticmethod
    def _poles(values: dict) -> dict[str, np.ndarray]:
        s = setup(values)
        b = s.bearing
        regulator = linear_loop(replace(s, use_estimate=False), with_filter=False)
        no_g = linear_loop(replace(s, use_estimate=False), current_loop=False, with_filter=False)
        return {"open-loop plant": np.array([b.open_loop_pole_rad_per_s, -b.open_loop_pole_rad_per_s],
                                            dtype=complex),
                "closed loop with G(s)": to_s(regulator.poles()),
                "closed loop without G(s)": to_s(no_g.poles()),
                "filter error": analysis.z_to_s(s.design.error_poles(), T)}

    @staticmethod
    def _liftoff_plot(runs: dict) -> Plot:
        """The noise-free lift-offs of both feedback sources (a stopped run leaves a gap)."""
        t = np.arange(round(LIFTOFF_RUN_S / T)) * T
        series = []
        for src, label, colour in (("measured", "raw-measurement PID", "#1f77b4"),
                                   ("estimated", "filter-PID", "#d62728")):
            x = np.full(t.size, np.nan)
            done = runs[src][0]["x_true_m"][: t.size]
            x[: done.size] = done * 1e6
            series.append((label, x, colour))
        return Plot("Noise-free lift-off (true position)", "time [ms]", "collar position x [µm]", t * 1e3,
                    tuple(series))

    @staticmethod
    def _filter_error_plot(errors: dict) -> Plot:
        """x̂ − x of the four filters in the noise-free lift-off on the nonlinear plant (``filter_errors``),
        its first ``FILTER_ERROR_PLOT_S`` (the errors have died out by then)."""
        t = np.arange(round(FILTER_ERROR_PLOT_S / T)) * T
        series = []
        for name, run in errors.items():
            error = np.full(t.size, np.nan)
            error[: run["error_m"].size] = run["error_m"][: t.size] * 1e6
            series.append((LABELS[name], error, COLOURS[name]))
        return Plot("Filters on the nonlinear plant (eq. 2): estimate error, first 40 ms of the noise-free lift-off",
                    "time [ms]",
                    "x̂ − x [µm]", t * 1e3, tuple(series))

    @staticmethod
    def _gain_plot(design) -> Plot:
        n = round(GAIN_HISTORY_MS * 1e-3 / T)
        gains, covariances = design.gain_history(n)
        t = np.arange(n) * T * 1e3
        return Plot("Kalman gain and σ from P0 over the first milliseconds", "time [ms]",
                    "gain or σ, scaled [1]", t,          # the legend says how each is scaled
                    (("K_x (x ← z)", gains[:, 0], "#d62728"),
                     ("K_v × 1 ms", gains[:, 1] * 1e-3, "#9467bd"),
                     ("σ_x / 5 µm", np.sqrt(np.maximum(covariances[:, 0, 0], 0.0)) / 5e-6, "#1f77b4")))

    @staticmethod
    def _current_noise_plot(s: ThrustSetup) -> Plot:
        sigmas_um = np.linspace(0.0, 50.0, 11)
        series = []
        for src, colour in (("measured", "#1f77b4"), ("estimated", "#d62728")):
            # the filter's R follows σ_v, so each point is its own loop (the raw PID's is linear in σ_v)
            std = [linear_loop(replace(s, use_estimate=src == "estimated", sensor_noise_m=max(v, 0.1) * 1e-6))
                   .output_std(v * 1e-6, s.force_noise_n)["current_command_a"] for v in sigmas_um]
            series.append((f"current-command noise, {'raw PID' if src == 'measured' else 'filter-PID'}",
                           np.array(std), colour))
        series.append(("current limit", np.full(sigmas_um.size, s.current_limit_a), "#000000"))
        return Plot("Current-command noise vs sensor noise (linear, no limit)", "sensor noise σ_v [µm]",
                    "standard deviation [A]", sigmas_um, tuple(series))

    def mode_matrices(self, values: dict) -> dict[str, tuple]:
        """The two measured-feedback loops and the filter's error by their states (paper 003: the
        collar's x, v of eq. 5, the current loop G(s) of Fig. 7, the PID's integral, its previous
        error (the difference quotient's one-sample delay) and its filtered D term; the filter's
        x, v error of eq. 13-17), in ``thrust_liftoff_linear._linear_step``'s order."""
        s = setup(values)
        collar = [("x [m]", "collar position/velocity (levitation mode)"),
                  ("v [m/s]", "collar position/velocity (levitation mode)")]
        g = [("G(s) state 1 [A]", "current loop G(s)"), ("G(s) state 2 [A]", "current loop G(s)")]
        derivative = "PID D term"
        pid = [("PID integral [A]", "PID integrator"), ("previous error [m]", derivative),
               ("D term [A]", derivative)]
        Phi, _, _ = s.design.matrices
        gain = s.design.steady_state[0]
        measured = replace(s, use_estimate=False)
        return {"closed loop with G(s)": (linear_loop(measured, with_filter=False).M, collar + g + pid, T),
                "closed loop without G(s)": (linear_loop(measured, current_loop=False, with_filter=False).M,
                                             collar + pid, T),
                "filter error": ((np.eye(2) - np.outer(gain, H)) @ Phi,
                                 [("x error [m]", "position/velocity estimate error"),
                                  ("v error [m/s]", "position/velocity estimate error")], T)}

    def pole_categories(self, values: dict) -> dict[str, PoleCategory]:
        return {"open-loop plant": PoleCategory.PLANT, "closed loop with G(s)": PoleCategory.CLOSED_LOOP,
                "closed loop without G(s)": PoleCategory.CLOSED_LOOP, "filter error": PoleCategory.FILTER_ERROR}

    def mode_names(self, values: dict, poles: dict[str, np.ndarray]) -> dict[str, list[str | None]]:
        """The open-loop plant's two poles (``analyse`` lists +a, then −a) by name."""
        return {"open-loop plant": ["collar position (unstable magnet pole)",
                                    "collar position (stable mirror of the magnet pole)"]}

    def simulation(self, values: dict) -> ThrustSimulation:
        s = setup(values)
        return ThrustSimulation(s, seed=int(values["seed"]), explanation=instability_note(s),
                                relaunch_s=values["relaunch_s"])

    def retune(self, simulation: ThrustSimulation, values: dict) -> ThrustSimulation:
        """A slider move changes the running experiment; a new start position relaunches it."""
        s = setup(values)
        if s.start_position_m != simulation.setup.start_position_m:
            return self.simulation(values)
        simulation.retuned(s)
        simulation.explanation = instability_note(s)
        simulation.relaunch_s = values["relaunch_s"]
        return simulation

    def scene(self, values: dict) -> ThrustBearingScene:
        """The collar between its stator halves, gaps and motion drawn ×40."""
        return ThrustBearingScene(values)

    def report_figures(self, values: dict) -> list:
        """Fig. 8 (the noise-free lift-offs of both controllers), Fig. 11's accuracy in a noisy run
        (the estimate error inside ±3σ) and the current-command noise over the sensor noise."""
        from lab_modules.exercises._figures import analysis_plots, plot_figure, scope_figure
        plots = analysis_plots(self, values, ("Noise-free lift-off", "Current-command noise"))
        return [plot_figure(plots[0]),
                scope_figure(self, [("", values)], self.default_duration_s, "Lift-off with sensor noise "
                             "(the chosen feedback)", charts=("Lift-off: collar position", "Estimation error x̂ − x, ±3σ")),
                plot_figure(plots[1])]

    def live_readouts(self, trace: dict[str, np.ndarray]) -> list[tuple[str, float, str]]:
        error, sigma = trace["estimation_error_m"], trace["x_sigma_m"]
        command = trace["current_command_a"]
        return [("Std of true x", float(np.std(trace["x_true_m"])) * 1e6, "µm"),
                ("Std of measured z", float(np.std(trace["x_measured_m"])) * 1e6, "µm"),
                ("Std of estimate x̂", float(np.std(trace["x_estimated_m"])) * 1e6, "µm"),
                ("Std of the current command", float(np.std(command)), "A"),
                ("Time at the current limit", 100.0 * float(np.mean(np.abs(command) >= trace["current_limit_a"])),
                 "%"),
                ("Estimate error inside ±3σ", 100.0 * float(np.mean(np.abs(error) <= 3.0 * sigma)), "%")]

    def metrics(self, values: dict, duration_s: float) -> dict:
        s = setup(values)
        b = s.bearing
        design = s.design
        gain, _, _ = design.steady_state
        filter_z = design.error_poles()
        radius, damping = pole_damping(filter_z)
        regulator_z = linear_loop(replace(s, use_estimate=False), with_filter=False).poles()
        Phi, _, _ = b.taylor_discretisation()
        Phi_e, _, _ = b.exact_discretisation()
        out = {"bias_current_a": b.bias_current_a,
               "force_constant_n_m2_per_a2": b.force_constant_n_m2_per_a2,
               "open_loop_pole_rad_per_s": b.open_loop_pole_rad_per_s,
               "smallest_stable_kp_a_per_mm": b.critical_proportional_gain_a_per_m * MM,
               "taylor_vs_exact_max_difference": float(np.max(np.abs(Phi - Phi_e))),
               "filter_q_from_p0_n2": PAPER_Q_N2}
        # noise-free lift-off, both feedback sources
        runs = {src: liftoff(values, src, min(duration_s, LIFTOFF_RUN_S)) for src in SOURCES}
        for src in SOURCES:
            f = liftoff_figures(runs[src][0], s.start_position_m)
            suffix = f"_{src}_feedback"
            out[f"liftoff_overshoot_percent{suffix}"] = f["overshoot_percent"]
            out[f"liftoff_peak_time_ms{suffix}"] = f["peak_time_s"] * 1e3
            out[f"settling_time_2pct_s{suffix}"] = f["settling_time_s"]
            out[f"status_noise_free{suffix}"] = runs[src][1]
        out["liftoff_peak_time_ms"] = out["liftoff_peak_time_ms_measured_feedback"]
        out["settling_time_2pct_s"] = out["settling_time_2pct_s_measured_feedback"]
        n = min(len(runs[src][0]["time_s"]) for src in SOURCES)
        out["liftoff_max_difference_um"] = (float(np.max(np.abs(runs["measured"][0]["x_true_m"][:n]
                                                               - runs["estimated"][0]["x_true_m"][:n]))) * 1e6
                                            if n else float("nan"))
        out["liftoff_gap"] = liftoff_gap_evidence(s, min(duration_s, LIFTOFF_RUN_S))
        seeds = range(int(values["seed"]), int(values["seed"]) + int(values["seeds"]))
        if s.nonlinear:                           # where the EKF and the linear filter differ (a few s of CPU)
            out["filters"] = comparison(s, duration_s, seeds, steady_window_start_s(duration_s))
        # noisy runs: steady state and lift-off statistics over the seeds
        per_seed = {key: [] for key in ("std_z_measured", "std_xhat_estimated", "std_x_measured", "std_x_estimated",
                                        "current_std_measured", "current_std_estimated", "overshoot_measured",
                                        "overshoot_estimated", "limit_measured", "limit_estimated", "within_3sigma")}
        status = {}
        for seed in seeds:
            for src in SOURCES:
                sim = ThrustSimulation(replace(s, use_estimate=src == "estimated"), seed=seed)
                trace = sim.run(duration_s)
                status[src] = sim.status_message() or status.get(src, "ok")   # any stop is reported
                per_seed[f"overshoot_{src}"].append(
                    liftoff_figures(trace, s.start_position_m)["overshoot_percent"])
                command = trace["current_command_a"]
                per_seed[f"limit_{src}"].append(100.0 * float(np.mean(np.abs(command) >= s.current_limit_a))
                                                if command.size else float("nan"))
                per_seed[f"std_x_{src}"].append(steady_std(trace, "x_true_m", duration_s))
                per_seed[f"current_std_{src}"].append(steady_std(trace, "current_command_a", duration_s))
                if src == "measured":
                    per_seed["std_z_measured"].append(steady_std(trace, "x_measured_m", duration_s))
                else:
                    per_seed["std_xhat_estimated"].append(steady_std(trace, "x_estimated_m", duration_s))
                    after = trace["time_s"] >= steady_window_start_s(duration_s)
                    inside = np.abs(trace["estimation_error_m"][after]) <= 3.0 * trace["x_sigma_m"][after]
                    per_seed["within_3sigma"].append(100.0 * float(np.mean(inside)) if inside.size else float("nan"))
        if len(per_seed["overshoot_measured"]) > 1:        # a median's standard error needs a spread
            out["noisy_liftoff_overshoot_median_se_percent_measured_feedback"] = median_standard_error(
                per_seed["overshoot_measured"])
        ratio = np.array(per_seed["std_z_measured"]) / np.array(per_seed["std_xhat_estimated"])
        current_ratio = np.array(per_seed["current_std_measured"]) / np.array(per_seed["current_std_estimated"])
        predicted = {src: linear_loop(replace(s, use_estimate=src == "estimated")).output_std(
            s.sensor_noise_m, s.force_noise_n) for src in SOURCES}
        out.update({
            "steady_std_ratio": float(np.mean(ratio)),
            "steady_std_ratio_per_seed": ratio.tolist(),
            "steady_std_ratio_predicted": predicted["measured"]["x_measured_m"]
            / max(predicted["estimated"]["x_estimated_m"], 1e-300),
            "steady_std_z_measured_feedback_um": float(np.mean(per_seed["std_z_measured"])) * 1e6,
            "steady_std_xhat_estimated_feedback_um": float(np.mean(per_seed["std_xhat_estimated"])) * 1e6,
            "steady_std_x_true_measured_feedback_um": float(np.mean(per_seed["std_x_measured"])) * 1e6,
            "steady_std_x_true_estimated_feedback_um": float(np.mean(per_seed["std_x_estimated"])) * 1e6,
            "current_noise_ratio": float(np.mean(current_ratio)),
            "current_noise_std_measured_feedback_a": float(np.mean(per_seed["current_std_measured"])),
            "current_noise_std_estimated_feedback_a": float(np.mean(per_seed["current_std_estimated"])),
            "estimate_within_3sigma_percent": float(np.mean(per_seed["within_3sigma"])),
            "noisy_liftoff_overshoot_median_percent_measured_feedback": float(np.median(per_seed["overshoot_measured"])),
            "noisy_liftoff_overshoot_median_percent_estimated_feedback":
                float(np.median(per_seed["overshoot_estimated"])),
            "noisy_liftoff_overshoot_percent_per_seed_measured_feedback": per_seed["overshoot_measured"],
            "noisy_liftoff_overshoot_percent_per_seed_estimated_feedback": per_seed["overshoot_estimated"],
            "time_at_current_limit_percent_measured_feedback": float(np.mean(per_seed["limit_measured"])),
            "time_at_current_limit_percent_estimated_feedback": float(np.mean(per_seed["limit_estimated"])),
            "steady_state_kalman_gain": gain.tolist(),
            "filter_error_poles": pairs(filter_z),
            "filter_pole_magnitude": radius,
            "filter_pole_damping": damping,
            "closed_loop_poles_rad_per_s": pairs(to_s(regulator_z)),
            "closed_loop_stable": bool(np.max(np.abs(regulator_z)) < 1.0),
            "status_measured_feedback": status["measured"],
            "status_estimated_feedback": status["estimated"],
            "steady_window_s": [steady_window_start_s(duration_s), duration_s],
            "seeds": int(values["seeds"]),
            "duration_s": duration_s,
        })
        return out


EXERCISE = ThrustLiftoff()
