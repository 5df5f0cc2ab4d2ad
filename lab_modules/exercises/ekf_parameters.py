"""Exercise ``ekf_parameters``: an EKF that estimates k_i and k_x (paper 000, §III-A).

The filter is ``extended_kalman.ParameterEKF``: the linearised bearing model
of §II with the state augmented by the force-current and force-position
factors (eq. 8-9), running against the nonlinear plant of eq. 10-12 held by
the paper's PID.  The paper reports that the parameter estimates need "an
adequate system excitement", realised by a PRBS on the reference position.
Here the student switches that PRBS on and off and watches k_i and k_x (with
their ±3σ bands) against the true local values, the analytic derivatives of
eq. 10 at the rotor's true position and current.

Choices not in the paper (worksheet "Choices"):

* Initial guesses k_i = 100 N/A, k_x = 0.6 N/µm (about 22 % and 25 % below
  the rated values) with a 30 % initial standard deviation: the filter must
  find the parameters, not start on them.
* Parameter process noise q_ki = 1e-4 (N/A)², q_kx = 1e2 (N/m)² per sample:
  a random walk of about 1 % of the rated values per second, slow against
  the 2 s run but enough to follow a change of operating point.
* q_33 = 1e-3 A² (the amplifier model's error, 1 % of i0 per sample); the
  paper's eq. 17 value 0.43 A² was tuned on the real amplifier, whose model
  error the simulated plant does not have (see ``ekf_disturbance``).
* PRBS 8 µm, 10 ms bits: the PID's derivative turns every reference step into
  a current kick (peak about 0.5 A per µm of amplitude: 3.9 A at 8 µm, beyond
  i0 = 3.1 A); much larger steps drive the current
  where eq. 10 is far from linear and bias the linear model's k_x (try 12 µm,
  5 ms), much smaller ones drown in the 1.87 A current-sensor noise.
* An ideal position sensor by default (T_mx = 0): eq. 9 has no sensor lag, so
  a lagging sensor biases the estimates (a worksheet task).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from lab_modules import analysis
from lab_modules.claims import Claim
from lab_modules.estimators import extended_kalman as ef
from lab_modules.exercises import Analysis, Chart, Exercise, Plot, PoleCategory, Series
from lab_modules.exercises._common import (
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
    Prbs,
    column,
    loop_at_plant_input,
    rest_current_a,
)
from lab_modules.loops.radial_axis_experiment import AxisSetup
from lab_modules.parameters import Parameter, in_si
from lab_modules.plants.radial_bearing import RIG
from lab_modules.scenes.bearing import ESTIMATE_RED, MEASURED_GREY, BearingScene, Ghost

T = RIG.sample_time_s
KI_RATED, KX_RATED = RIG.ki_n_per_a, RIG.kx_n_per_m
INITIAL_SIGMA_FRACTION = 0.3
#: The final estimate is compared with the mean true local value over this window.
TRUTH_WINDOW_S = 0.1
CONVERGED_PERCENT = 5.0
CONVERGENCE_LABEL = (f"Both estimates within ±{CONVERGED_PERCENT:g} % of k_i, k_x at x_0 since t "
                     "(time since reset)")

P = Parameter
PARAMETERS = (
    P("prbs_amplitude_um", "PRBS amplitude", "µm", 8.0, 0.0, 30.0,
      "Amplitude of the PRBS superimposed on the reference position (§III-A); 0 = no excitation.",
      step=0.5, group="Excitation"),
    P("prbs_bit_time_ms", "PRBS bit time", "ms", 10.0, 1.0, 50.0,
      "How long each bit of the PRBS is held.", step=0.5, group="Excitation"),
    P("reference_offset_um", "Operating point x_0", "µm", 0.0, -150.0, 150.0,
      "Reference position the PRBS is added to; the true k_i, k_x change with it (eq. 10).",
      step=5.0, group="Excitation"),
    P("initial_ki_n_per_a", "Initial k_i estimate", "N/A", 100.0, 20.0, 300.0,
      f"The filter's starting value of k_i (rated {KI_RATED} N/A; not in the paper).",
      step=1.0, group="Extended Kalman filter"),
    P("initial_kx_n_per_um", "Initial k_x estimate", "N/µm", 0.6, 0.1, 3.0,
      f"The filter's starting value of k_x (rated {KX_RATED * 1e-6:.3f} N/µm; not in the paper).",
      step=0.01, group="Extended Kalman filter"),
    P("filter_q_ki", "Filter q_ki", "(N/A)²", 1e-4, 1e-10, 1.0,
      "Process noise of k_i per sample (its random walk, §II 'dp/dt = 0 + ξ'; not in the paper).",
      log=True, group="Extended Kalman filter"),
    P("filter_q_kx", "Filter q_kx", "(N/m)²", 1e2, 1e-4, 1e8,
      "Process noise of k_x per sample (not in the paper).", log=True, group="Extended Kalman filter"),
    *EKF_VARIANCES,
    *PLANT_NOISE,
    P("sensor_lag_us", "Sensor lag T_mx", "µs", 0.0, 0.0, 1000.0,
      "Plant's position-sensor lag, eq. 12 (eq. 9 has none; the rig's is about 200 µs).",
      step=10.0, group="Plant"),
    P("feedback", "Feedback source", "", "measured", choices=("measured", "estimated"),
      description="Position the PID acts on: the sensor's or the filter's estimate.", group="Controller"),
    *PAPER_PID,
    SEED,
    replace(TIME_SCALE, default=0.2),   # a scope window of 1 s
)


def setup(values: dict, excitation: bool = True) -> EKFLoopSetup:
    """The experiment described by the parameter values (PRBS off: ``excitation=False``)."""
    si = in_si(PARAMETERS, values)
    initial = np.array([0.0, 0.0, 0.0, values["initial_ki_n_per_a"], si["initial_kx_n_per_um"]])
    sigma0 = np.array([10e-6, 1e-3, 0.1, INITIAL_SIGMA_FRACTION * KI_RATED, INITIAL_SIGMA_FRACTION * KX_RATED])
    amplitude = si["prbs_amplitude_um"] if excitation else 0.0
    return EKFLoopSetup(
        model=ef.LINEARISED,
        filter_x0=initial, filter_P0=np.diag(sigma0**2),
        filter_Q=np.diag([0.0, values["filter_q_velocity"], values["filter_q_current"],
                          values["filter_q_ki"], values["filter_q_kx"]]),
        plant_sensor_lag_s=si["sensor_lag_us"],
        **ekf_loop_fields(values),
        reference=Prbs(amplitude, si["prbs_bit_time_ms"], si["reference_offset_um"]))


def linear_poles(axis: AxisSetup) -> dict[str, np.ndarray]:
    """Open-loop plant, closed loop and filter error poles [rad/s] of ``linear_axis``."""
    K, _ = axis.steady_state_filter
    A, C = np.asarray(axis.model.A), np.asarray(axis.model.C)
    return {"open-loop plant": np.linalg.eigvals(np.asarray(RIG.continuous_model(axis.sensor_lag_s).A)),
            "closed loop (linear, rated k_i, k_x)": analysis.z_to_s(analysis.loop_poles(axis.loop()), T),
            "filter error (x, v, i at rated k_i, k_x)": analysis.z_to_s(np.linalg.eigvals(A - A @ K @ C), T)}


def operating_point(offset_m: float) -> tuple[float, float]:
    """(k_x [N/m], k_i [N/A]) of eq. 10 at rest at x = offset: the current that
    balances the force, f_m(x, i) = 0, found by Newton's method on eq. 10."""
    return ef.local_factors(offset_m, rest_current_a(RIG, offset_m), ef.physics_vector(RIG))


def final_errors(trace: np.ndarray) -> dict[str, float]:
    """Final estimates against the mean true local values of the last ``TRUTH_WINDOW_S``."""
    window = slice(-max(1, int(TRUTH_WINDOW_S / T)), None)
    result = {}
    for name in ("ki", "kx"):
        unit = "n_per_a" if name == "ki" else "n_per_m"
        true = float(np.mean(column(trace, f"{name}_true_{unit}")[window]))
        estimate = float(column(trace, f"{name}_estimated_{unit}")[-1])
        sigma = float(column(trace, f"{name}_sigma_{unit}")[-1])
        result[name] = (estimate, true, 100.0 * (estimate / true - 1.0), 300.0 * sigma / abs(true))
    return result


class ConvergenceWatch:
    """The EKF loop's run (``EKFLoopSimulation``) with one more trace column, ``within_band_since_s``:
    the time since reset [s] from which both estimates have stayed within ±``CONVERGED_PERCENT`` of
    the true k_i, k_x at the operating point (eq. 10 at rest at x_0, the analysis's readouts), NaN
    while either is outside.  The true local values on the scope move with the PRBS (k_x by about
    20 %), the estimates of a linear model cannot follow them, so the band is the operating point's."""

    def __init__(self, simulation: EKFLoopSimulation, truth: tuple[float, float]):
        """``truth``: (k_x [N/m], k_i [N/A]) at the operating point."""
        self.simulation, self.truth = simulation, truth
        self.columns = (*simulation.columns, "within_band_since_s")
        self.sample_time_s = simulation.sample_time_s
        self.entered_s = float("nan")         # start of the current run of samples inside the band

    def retuned(self, simulation: EKFLoopSimulation, truth: tuple[float, float]) -> ConvergenceWatch:
        """The watch over the retuned run: it carries on while the operating point stays."""
        watch = ConvergenceWatch(simulation, truth)
        if truth == self.truth:
            watch.entered_s = self.entered_s
        return watch

    def advance(self, n_steps: int) -> np.ndarray:
        trace = self.simulation.advance(n_steps)
        kx, ki = self.truth
        inside = ((np.abs(column(trace, "ki_estimated_n_per_a") / ki - 1.0) * 100.0 <= CONVERGED_PERCENT)
                  & (np.abs(column(trace, "kx_estimated_n_per_m") / kx - 1.0) * 100.0 <= CONVERGED_PERCENT))
        was_inside = np.concatenate(([np.isfinite(self.entered_s)], inside[:-1]))
        entered = inside & ~was_inside                          # the samples where a run inside begins
        latest_entry = np.maximum.accumulate(np.where(entered, np.arange(len(trace)), -1))
        since = np.where(latest_entry >= 0, trace[np.maximum(latest_entry, 0), 0], self.entered_s)
        since[~inside] = np.nan
        if len(trace):
            self.entered_s = float(since[-1])
        return np.column_stack([trace, since])

    def __getattr__(self, name: str):
        """Everything else is the loop's own (``status_message``, ``filter_state``, the filter's P …)."""
        if name == "simulation":                  # not set yet: no loop to ask
            raise AttributeError(name)
        return getattr(self.simulation, name)


CLAIMS = (
    Claim("paper 000 §III-A", "k_i estimate error with PRBS excitation", "converges (no number)",
          "ki_estimate_error_percent", (-5, 5), "%",
          note="final estimate against the mean true local value (eq. 10's derivative) of the last 100 ms"),
    Claim("paper 000 §III-A", "k_x estimate error with PRBS excitation", "converges (no number)",
          "kx_estimate_error_percent", (-5, 5), "%"),
    Claim("paper 000 §III-A", "largest parameter error without excitation (same run, PRBS off)",
          "“a proper estimation … does require an adequate system excitement”",
          "largest_error_percent_no_excitation", (10, None), "%"),
)


class EkfParameters(Exercise):
    name = "ekf_parameters"
    title = "EKF estimating k_i and k_x (needs excitation)"
    worksheet = "ekf_parameters.md"
    parameters = PARAMETERS
    default_duration_s = 2.0
    claims = CLAIMS
    locus = ("pid_gain", "closed loop (linear, rated k_i, k_x)")
    key_readouts = (CONVERGENCE_LABEL, "k_i error now", "k_x error now", "True k_i at the operating point",
                    "True k_x at the operating point")
    charts = (
        Chart("Force-current factor k_i", "N/A", (
            Series("estimate", "ki_estimated_n_per_a", 1.0, "#d62728"),
            Series("true local", "ki_true_n_per_a", 1.0, "#1f77b4")),
            band=("ki_estimated_n_per_a", "ki_sigma_n_per_a"), band_in_range=False),   # a ±5 % band in view
        Chart("Force-position factor k_x", "N/µm", (
            Series("estimate", "kx_estimated_n_per_m", 1e-6, "#d62728"),
            Series("true local (grows with i²)", "kx_true_n_per_m", 1e-6, "#1f77b4")),
            band=("kx_estimated_n_per_m", "kx_sigma_n_per_m"), band_in_range=False),
        Chart("Rotor position", "µm", (
            Series("measured", "x_measured_m", 1e6, "#b0b0b0"),
            Series("reference", "reference_m", 1e6, "#2ca02c"),
            Series("true", "x_true_m", 1e6, "#1f77b4"))),
        Chart("Coil current", "A", (Series("control current i", "current_a", 1.0, "#2ca02c"),)),
    )

    def model(self, values: dict) -> dict:
        axis = setup(values)
        return {"filter": "extended Kalman filter, linearised model augmented by k_i, k_x (eq. 8-9)",
                "states": ["x [m]", "v [m/s]", "i [A]", "k_i [N/A]", "k_x [N/m]"],
                "inputs": ["i_ref [V]"], "outputs": ["K_mx x [V]", "K_mi i [V]"], "sample_time_s": T,
                "prediction": "RK4 of eq. 9 over T; Phi = I + F T + F^2 T^2 / 2 (eq. 15)",
                "G": ef.measurement_matrix(ef.LINEARISED).tolist(),
                "Q": axis.filter_Q.tolist(), "R": np.diag(axis.filter_R_diag).tolist(),
                "x0": axis.filter_x0.tolist(), "P0": axis.filter_P0.tolist()}

    def open_loops(self, values: dict) -> dict:
        """The PID loop linearised at the operating point x_0, the EKF at its converged estimates."""
        return {f"PID, {values['feedback']} x": loop_at_plant_input(
            setup(values), in_si(PARAMETERS, values)["reference_offset_um"])}

    def analyse(self, values: dict) -> Analysis:
        si = in_si(PARAMETERS, values)
        offset = si["reference_offset_um"]
        kx, ki = operating_point(offset)
        x_um = np.linspace(-200.0, 200.0, 81)
        factors = np.array([operating_point(x * 1e-6) for x in x_um])
        marker_kx, marker_ki = np.full(x_um.size, np.nan), np.full(x_um.size, np.nan)
        nearest = int(np.argmin(np.abs(x_um - offset * 1e6)))
        marker_kx[nearest], marker_ki[nearest] = factors[nearest, 0] * 1e-6, factors[nearest, 1]
        plots = [
            Plot("k_x of eq. 10 at rest across the gap", "rotor position x [µm]", "k_x [N/µm]", x_um,
                 (("k_x at rest", factors[:, 0] * 1e-6, "#1f77b4"),
                  ("operating point", marker_kx, "#d62728"))),
            Plot("k_i of eq. 10 at rest across the gap", "rotor position x [µm]", "k_i [N/A]", x_um,
                 (("k_i at rest", factors[:, 1], "#1f77b4"), ("operating point", marker_ki, "#d62728"))),
        ]
        readouts = [
            ("True k_i at the operating point", ki, "N/A"),
            ("True k_x at the operating point", kx * 1e-6, "N/µm"),
            ("Initial k_i error", 100.0 * (values["initial_ki_n_per_a"] / ki - 1.0), "%"),
            ("Initial k_x error", 100.0 * (si["initial_kx_n_per_um"] / kx - 1.0), "%"),
        ]
        poles = linear_poles(linear_axis(values))
        notes = [("The true local values on the scope are the derivatives of eq. 10 at the rotor's "
                 "true position and current; they move with the PRBS, the estimates cannot "
                 "(eq. 9 is linear). k_x ∝ (i0 + i)² + (i0 − i)² = 2 (i0² + i²): where a PRBS edge "
                 "drives the control current towards ±i0 the true local k_x nearly doubles for a "
                 "few milliseconds, the spikes on its chart.")]
        return Analysis(readouts, poles, notes, plots)

    def pole_categories(self, values: dict) -> dict[str, PoleCategory]:
        return {"open-loop plant": PoleCategory.PLANT,
                "closed loop (linear, rated k_i, k_x)": PoleCategory.CLOSED_LOOP,
                "filter error (x, v, i at rated k_i, k_x)": PoleCategory.FILTER_ERROR}

    def mode_names(self, values: dict, poles: dict[str, np.ndarray]) -> dict[str, list[str | None]]:
        """The open-loop plant's poles by name (the loops' poles keep their generic kind)."""
        return {"open-loop plant": axis_plant_names(poles["open-loop plant"])}

    def mode_matrices(self, values: dict) -> dict[str, tuple]:
        """The linear loop and its filter error by their states (paper 000 eq. 1-4, 12-13; PID §IV)."""
        return axis_mode_matrices(linear_axis(values), "closed loop (linear, rated k_i, k_x)",
                                  "filter error (x, v, i at rated k_i, k_x)")

    def locus_matrices(self, values: dict, factors: tuple[float, ...]) -> tuple[list[np.ndarray], float]:
        """The linear loop's state matrices (the states in the feedback) at these PID gains K."""
        axis = linear_axis(values)
        return [axis.loop_matrix(factor / values["pid_gain"]) for factor in factors], T

    def simulation(self, values: dict) -> ConvergenceWatch:
        return ConvergenceWatch(EKFLoopSimulation(setup(values), seed=int(values["seed"])),
                                operating_point(values["reference_offset_um"] * 1e-6))

    def retune(self, simulation: ConvergenceWatch, values: dict) -> ConvergenceWatch:
        """A slider move changes the running experiment (switch the PRBS on and watch)."""
        return simulation.retuned(simulation.simulation.retuned(setup(values)),
                                  operating_point(values["reference_offset_um"] * 1e-6))

    def scene(self, values: dict) -> BearingScene:
        """The bearing under the PRBS excitation (tens of micrometres: drawn ×2000)."""
        return BearingScene(values, exaggeration=2000, force_scale_m_per_n=2e-4,
                            true_column="x_true_m", current_column="current_a",
                            ghosts=(Ghost("measured", "x_measured_m", MEASURED_GREY),
                                    Ghost("estimate", "x_estimated_m", ESTIMATE_RED)))

    def metrics(self, values: dict, duration_s: float) -> dict:
        n_steps = round(duration_s / T)
        out = {}
        for excitation, suffix in ((True, ""), (False, "_no_excitation")):
            sim = EKFLoopSimulation(setup(values, excitation), seed=int(values["seed"]))
            trace = sim.advance(n_steps)
            errors = final_errors(trace)
            for name, (estimate, true, error, three_sigma) in errors.items():
                unit = "n_per_a" if name == "ki" else "n_per_m"
                out[f"{name}_estimate_error_percent{suffix}"] = error
                out[f"{name}_estimate_{unit}{suffix}"] = estimate
                out[f"{name}_true_{unit}{suffix}"] = true
                out[f"{name}_estimate_3sigma_percent{suffix}"] = three_sigma
                out[f"{name}_converged{suffix}"] = bool(abs(error) <= CONVERGED_PERCENT)
            out[f"mean_nis{suffix}"] = float(np.mean(column(trace, "nis")))
            out[f"status{suffix}"] = sim.status_message() or "ok"
        out["largest_error_percent_no_excitation"] = max(abs(out["ki_estimate_error_percent_no_excitation"]),
                                                         abs(out["kx_estimate_error_percent_no_excitation"]))
        out["converged_criterion"] = (f"final estimate within {CONVERGED_PERCENT:g} % of the mean true "
                                      f"local value over the last {TRUTH_WINDOW_S * 1e3:g} ms")
        out["duration_s"] = n_steps * T
        return out

    def report_figures(self, values: dict) -> list:
        """The estimates converging with the PRBS and wandering without it (2 s runs)."""
        from lab_modules.exercises._figures import scope_figure
        runs = [("with PRBS", values), ("without excitation", {**values, "prbs_amplitude_um": 0.0})]
        return [scope_figure(self, runs, self.default_duration_s, "Parameter estimates ±3σ against the true "
                             "local values", charts=("Force-current factor k_i", "Force-position factor k_x"))]

    def live_readouts(self, trace: dict[str, np.ndarray]) -> list[tuple[str, float, str]]:
        if len(trace.get("ki_true_n_per_a", ())) == 0:
            return []
        since = float(trace["within_band_since_s"][-1])        # NaN while one of them is outside
        converged = [(CONVERGENCE_LABEL, since, "s")] if np.isfinite(since) else []
        return converged + [
            (f"{label} error now", 100.0 * (trace[f"{n}_estimated_{u}"][-1] / trace[f"{n}_true_{u}"][-1] - 1), "%")
            for label, n, u in (("k_i", "ki", "n_per_a"), ("k_x", "kx", "n_per_m"))]


EXERCISE = EkfParameters()
