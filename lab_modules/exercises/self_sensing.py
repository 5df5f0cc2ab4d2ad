"""Exercise ``self_sensing``: the air gap from the PWM current ripple, and its
error budget (paper 001: Glück, Kemmetmüller, Kugi, Tump, "Messfehleranalyse
für die Positionsschätzung eines sensorlosen Magnetlagersystems", VDI
Mechatronik 2011).

A ferrite ball hangs under a ferrite core (reluctance model eq. 1-2); a full
bridge drives the coil with ±v_bat (eq. 3-4).  There is no position sensor:
each PWM half period's current ripple gives an inductance L̂ᴵ, L̂ᴵᴵ by least
squares (eq. 5-10), their weighted mean L̄ (eq. 18) cancels a resistance
error and the ball's motion, and eq. 2 turns L̄ into the gap ŝ.  Eq. 28-32
predict the spread of every estimate from the residuals of its own fit.

Parameters: the measurement errors of §4 (gains μ, η of eq. 19, offsets of
eq. 23) and §5 (noise σ(i), σ(v)), the resistance the estimator assumes, the
window, T_a and T_pwm, the two operating points and the transition time of
the paper's simulations (Fig. 2-7), v_bat.  Loop: the compiled 1 µs
simulation of ``loops.self_sensing_loop`` (prescribed 4 → 6 → 4 mm motion,
per-period duty controller).  Views: a live ripple zoom of the newest two
PWM periods (``live_plots``: every 8th sample, windows shaded, fitted lines);
inductance, gap and errors per PWM period with ±3σ̂ bands, σ̂ traces; the
Analysis tab shows the ripple at every sample and a histogram.  The button
*Run Monte-Carlo* (``actions``) checks eq. 31 over 4 seeds.  Claims: §3-5 of
the paper with the lab's parameter set (``plants.self_sensing_ball``).
"""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from lab_modules.claims import Claim
from lab_modules.estimators.ripple_inductance import predicted_sigma_inductance_h
from lab_modules.loops.self_sensing_levitation import LevitatedLoop
from lab_modules.loops.self_sensing_loop import (
    COLUMN,
    COLUMNS,
    TRAJECTORIES,
    SelfSensingLoop,
    SelfSensingSetup,
)
from lab_modules.memo import remembered
from lab_modules.parameters import Parameter, in_si
from lab_modules.scenes.self_sensing import SelfSensingScene

from . import POLE_MAP, SCOPE, Action, Analysis, Chart, Exercise, Plot, PoleCategory, Series
from . import _self_sensing_geometry as geometry
from . import _self_sensing_levitation as levitation
from ._self_sensing_statistics import (
    IDEAL,
    eq25_shift_h,
    moving_offset_shift,
    statistics,
    trajectory_statistics,
)
from ._self_sensing_views import RIPPLE_PERIODS, histogram, live_readouts, monte_carlo_views, ripple_plots

SAMPLE_TIMES_US = ("0.5", "1", "2")
PWM_MODES = ("fixed T_pwm", "T_pwm = 1024 T_a")
POSITION_SOURCES = ("averaged L̄ (eq. 18)", "phase I only", "phase II only")
SETTLE_PERIODS = 40          # periods before a stationary run is measured (the duty settles in 2-3)
NOISY_PERIODS = 5000         # stationary periods per gap with noise: coverage of ±3σ̂ over ≥ 5000 periods
QUIET_PERIODS = 300          # stationary periods per gap without noise
LAST_PERIODS = 500           # the live "empirical std" window
LIVE_RIPPLE_POINTS = 256     # samples per live ripple plot (every 8th of 2 × 1024): 1 kB per series and update
HELD_PERIODS = 300           # the analysis's stationary run at each gap
MONTE_CARLO_SEEDS = 4        # the Monte-Carlo button: seeds × periods held at one gap
MONTE_CARLO_PERIODS = 1250
GAPS = ("gap_1", "gap_2")
PHASES = ("phase_1", "phase_2")

P = Parameter
PARAMETERS = (
    P("sigma_current_ma", "Current noise σ(i)", "mA", 1.0, 0.0, 20.0,
      "Standard deviation of the current measurement (§5: 1 mA; the paper calls it a variance).",
      step=0.01, group="Measurement"),
    P("sigma_voltage_mv", "Voltage noise σ(v)", "mV", 15.0, 0.0, 500.0,
      "Standard deviation of the voltage measurement (§5: 15 mV).", step=0.1, group="Measurement"),
    P("current_gain", "Current gain error μ", "", 1.0, 0.8, 1.2,
      "Eq. 19: i = μ i_m (§4.1 simulates μ = 1.05).", step=0.001, group="Measurement"),
    P("voltage_gain", "Voltage gain error η", "", 1.0, 0.8, 1.2,
      "Eq. 19: v = η v_m (§4.1 simulates η = 1.05).", step=0.001, group="Measurement"),
    P("current_offset_ma", "Current offset Δi", "mA", 0.0, -300.0, 300.0,
      "Eq. 23: i = i_m + Δi (§4.2: 0.05 ī = 75 mA).", step=1.0, group="Measurement"),
    P("voltage_offset_v", "Voltage offset Δv", "V", 0.0, -2.0, 2.0,
      "Eq. 23: v = v_m + Δv (§4.2: 0.05 v_bat = 0.57 V).", step=0.01, group="Measurement"),
    P("resistance_ratio", "Assumed resistance R̂/R", "", 1.0, 0.5, 1.5,
      "The resistance the estimator uses (eq. 7, 11) relative to the coil's 2.5 Ω.", step=0.01,
      group="Estimator"),
    P("trim_samples", "Window trim (per 1024 samples)", "samples", 8, 0, 100,
      "Samples left out at both ends of each phase, away from the switching edges (§3.1), counted per "
      "1024 samples of PWM period: a fixed share of the period (16 samples at 2048 per period).",
      integer=True, step=1, group="Estimator"),
    P("position_from", "Position from", "", POSITION_SOURCES[0], choices=POSITION_SOURCES,
      description="Averaging on (eq. 18) or off: the gap from one half period's estimate alone.",
      group="Estimator"),
    P("equation_7", "Eq. 7 flux sum", "", "v − R̂ i", choices=("v − R̂ i", "v + R i (printed)"),
      description="The printed eq. 7 sums v_j + R i_j; Faraday's law (eq. 5) needs v_j − R̂ i_j.",
      group="Estimator"),
    P("equation_28", "Eq. 28 divisor", "", "M − d", choices=("M − d", "M + d (printed)"),
      description="Residual variance eᵀe/(M − d) is unbiased for d = 2 fitted parameters; the paper prints "
                  "M + d.", group="Estimator"),
    P("sample_time_us", "Sample time T_a", "µs", "1", choices=SAMPLE_TIMES_US,
      description="Sampling of current and voltage (paper: 1 µs).", group="Sampling"),
    P("pwm_mode", "PWM period", "", PWM_MODES[0], choices=PWM_MODES,
      description="fixed T_pwm: the slider below; T_pwm = 1024 T_a: the paper's ratio at any T_a.",
      group="Sampling"),
    P("pwm_period_us", "T_pwm (fixed)", "µs", 1024.0, 128.0, 4096.0,
      "PWM period when fixed (paper: 1024 T_a = 1.024 ms); rounded to whole samples.", step=1.0,
      group="Sampling"),
    P("trajectory", "Ball motion", "", TRAJECTORIES[0], choices=TRAJECTORIES,
      description="Prescribed gap: hold 0.35 s, smooth move to gap 2, hold, back (Fig. 2-7); or fixed.",
      group="Operating points"),
    P("gap_1_mm", "Gap 1", "mm", 4.0, 2.0, 8.0, "First operating point (paper: 4 mm).", step=0.01,
      group="Operating points"),
    P("gap_2_mm", "Gap 2", "mm", 6.0, 2.0, 8.0, "Second operating point (paper: 6 mm).", step=0.01,
      group="Operating points"),
    P("transition_s", "Transition time", "s", 0.3, 0.02, 2.0,
      "Duration of each move between the operating points (§5: 0.3 s).", step=0.01,
      group="Operating points"),
    P("battery_voltage_v", "Supply v_bat", "V", 11.4, 8.0, 24.0,
      "Bridge supply voltage (§4.2: 11.4 V); 8 V still holds the ball at 8 mm (R i_eq = 6.0 V).",
      step=0.1, group="Operating points"),
    P("seed", "Random seed", "", 0, 0, 2**31 - 1, "Seed of this lab's noise.", integer=True, step=1,
      group="Run"),
    P("time_scale", "Time scale", "×", 0.25, 0.01, 2.0,
      "Simulated seconds per wall-clock second in the browser (1 = real time).", log=True, group="Run"),
) + geometry.PARAMETERS + levitation.PARAMETERS


def setup(values: dict, **changes) -> SelfSensingSetup:
    """The experiment of the parameter values (``changes``: SelfSensingSetup fields to override)."""
    si = in_si(PARAMETERS, values)
    sample_time = si["sample_time_us"]
    if values["pwm_mode"] == PWM_MODES[1]:
        samples = 1024
    else:
        samples = round(si["pwm_period_us"] / sample_time)
    # a fixed share of the period, at most an eighth of it (the windows keep ≥ 20 samples at any duty)
    trim = min(round(values["trim_samples"] * samples / 1024), (samples - 40) // 8)
    gap_1, gap_2 = si["gap_1_mm"], si["gap_2_mm"]
    s = SelfSensingSetup(
        sample_time_s=sample_time, samples_per_period=samples, resistance_ratio=values["resistance_ratio"],
        printed_eq7=values["equation_7"] != "v − R̂ i", current_gain=values["current_gain"],
        voltage_gain=values["voltage_gain"], current_offset_a=si["current_offset_ma"],
        voltage_offset_v=values["voltage_offset_v"], sigma_current_a=si["sigma_current_ma"],
        sigma_voltage_v=si["sigma_voltage_mv"], trim_samples=trim, gap_1_m=gap_1, gap_2_m=gap_2,
        transition_s=values["transition_s"], trajectory=values["trajectory"],
        battery_voltage_v=values["battery_voltage_v"], printed_dof=values["equation_28"] != "M − d",
        rig=geometry.rig(values))
    return replace(s, **changes)


def fixed(values: dict, gap: str, **changes) -> SelfSensingSetup:
    """The experiment held at one operating point."""
    return setup(values, trajectory=TRAJECTORIES[1 if gap == "gap_1" else 2], **changes)


def coil_pole_set(gap_m: float) -> str:
    """The name of the pole set that holds the coil's pole −R/L at a gap [m] (``Analysis.poles``)."""
    return f"coil −R/L at {gap_m * 1e3:g} mm"


# -- derived per-period columns --------------------------------------------------------------------
EXTRA_COLUMNS = ("gap_shown_m", "sigma_gap_shown_m", "gap_error_m", "inductance_error_h", "zero",
                 "inductance_ratio", "voltage_gain_estimate", "gain_ratio_set")


def derived(rows: np.ndarray, s: SelfSensingSetup, source: str) -> np.ndarray:
    """The position the chosen estimate gives, with its σ̂ (eq. 32), the errors, and Fig. 2's gains
    μ̂ = L̄_m/L and η̂ = L/L̄_m (eq. 22; each reads its own gain when the other is 1) with the set μ/η."""
    c = COLUMN
    if source == POSITION_SOURCES[0]:
        gap, sigma_l, inductance = rows[:, c["gap_estimated_m"]], rows[:, c["sigma_inductance_mean_h"]], None
        sigma = rows[:, c["sigma_gap_m"]]
    else:
        phase = "1" if source == POSITION_SOURCES[1] else "2"
        inductance = rows[:, c[f"inductance_{phase}_h"]]
        sigma_l = rows[:, c[f"sigma_inductance_{phase}_h"]]
        with np.errstate(all="ignore"):
            gap = s.rig.gap_m(inductance)
            sigma = s.rig.position_sensitivity_m_per_h(inductance) * sigma_l
    truth = rows[:, c["inductance_true_h"]]
    ratio = rows[:, c["inductance_mean_h"]] / truth                         # eq. 22: L̄_m/L = μ/η
    return np.column_stack([gap, sigma, gap - rows[:, c["gap_true_m"]],
                            rows[:, c["inductance_mean_h"]] - truth, np.zeros(len(rows)), ratio, 1.0 / ratio,
                            np.full(len(rows), s.current_gain / s.voltage_gain)])


class SelfSensingSimulation:
    """The app's view of the loop: one row per PWM period; the raw samples of the newest
    two periods are kept for the live ripple zoom (``ripple``), never streamed."""

    columns = COLUMNS + EXTRA_COLUMNS

    def __init__(self, values: dict, loop: SelfSensingLoop | None = None):
        self.values = dict(values)
        self.loop = loop or (LevitatedLoop(setup(values), levitation.loop_control(values), seed=int(values["seed"]))
                             if levitation.levitated(values) else SelfSensingLoop(setup(values), seed=int(values["seed"])))
        self.sample_time_s = self.loop.setup.period_s
        self.wall_s, self.simulated_s = 0.0, 0.0
        self.ripple = (np.empty((0, 5)), np.empty(0))    # (raw samples of ≤ 2 periods, their duties)

    def advance(self, n_steps: int) -> np.ndarray:
        first = self.loop.period
        start = time.perf_counter()
        n = self.loop.setup.samples_per_period
        older, _ = self.loop.run(max(n_steps - RIPPLE_PERIODS, 0))
        newest, raw = self.loop.run(min(n_steps, RIPPLE_PERIODS), raw_samples=RIPPLE_PERIODS * n)
        rows = np.concatenate([older, newest])
        self.wall_s += time.perf_counter() - start
        n_steps = len(rows)                  # fewer once a levitated ball has left its reference
        self.simulated_s += n_steps * self.sample_time_s
        if n_steps:
            kept, duties = self.ripple
            self.ripple = (np.concatenate([kept, raw])[-RIPPLE_PERIODS * n:],
                           np.concatenate([duties, newest[:, COLUMN["duty"]]])[-RIPPLE_PERIODS:])
        t = (first + 0.5 + np.arange(n_steps)) * self.sample_time_s
        return np.column_stack([t, rows, derived(rows, self.loop.setup, self.values["position_from"])])

    def status_message(self) -> str:
        return self.loop.stop_message

    def realtime_factor(self) -> float:
        return self.simulated_s / self.wall_s if self.wall_s > 0 else float("nan")


# -- stationary runs and their statistics --------------------------------------------------------------
def stationary(values: dict, gap: str, periods: int | None = None, seed_offset: int = 0,
               **changes) -> np.ndarray:
    """Per-period rows at one fixed operating point after the duty has settled."""
    s = fixed(values, gap, **changes)
    if periods is None:
        periods = NOISY_PERIODS if (s.sigma_current_a > 0 or s.sigma_voltage_v > 0) else QUIET_PERIODS
    loop = SelfSensingLoop(s, seed=int(values["seed"]) + seed_offset)
    loop.run(SETTLE_PERIODS)
    rows, _ = loop.run(periods)
    return rows


@remembered(size=16)
def held_rows(values: dict, gap: str) -> np.ndarray:
    """The analysis's ``HELD_PERIODS`` PWM periods held at one gap (remembered: the Scope and the Analysis tab
    both read those at gap 1)."""
    return stationary(values, gap, periods=HELD_PERIODS)


def held_readouts(values: dict, s: SelfSensingSetup, gap: str) -> list[tuple[str, float, str]]:
    """The readouts of ``held_rows`` at one gap: inductance and current (eq. 2), the estimator's
    figures (eq. 18, 28-32) and the straight-ramp prediction of σ(L̂) over each window."""
    gap_m = s.gap_1_m if gap == "gap_1" else s.gap_2_m
    at = f"At {gap_m * 1e3:g} mm: "                  # the group a long list folds
    inductance = float(s.rig.inductance_h(gap_m))
    current = float(s.rig.equilibrium_current_a(gap_m))
    st = statistics(held_rows(values, gap))
    windows = [st["duty"] * s.samples_per_period - 2 * s.trim_samples + 1,
               (1 - st["duty"]) * s.samples_per_period - 2 * s.trim_samples + 1]
    v_bat = s.battery_voltage_v
    ramp = [predicted_sigma_inductance_h(inductance, s.sigma_current_a, v, round(m), s.sample_time_s)
            for v, m in zip((v_bat - s.rig.coil_resistance_ohm * current,
                             v_bat + s.rig.coil_resistance_ohm * current), windows)]
    return [
        (f"{at}L (eq. 2)", inductance * 1e3, "mH"),
        (f"{at}equilibrium current", current, "A"),
        (f"{at}duty χ", st["duty"], ""),
        (f"{at}Δiᴵ", st["delta_current_ma"][0], "mA"),
        (f"{at}Δiᴵᴵ", st["delta_current_ma"][1], "mA"),
        (f"{at}weight wᴵ (eq. 18)", st["weights"][0], ""),
        (f"{at}weight wᴵᴵ (eq. 18)", st["weights"][1], ""),
        (f"{at}L̂ᴵ error", st["half_period_error_percent"]["phase_1"], "%"),
        (f"{at}L̂ᴵᴵ error", st["half_period_error_percent"]["phase_2"], "%"),
        (f"{at}L̄/L", st["inductance_ratio"], ""),
        (f"{at}position bias", st["position_bias_um"], "µm"),
        (f"{at}σ̂(i) (eq. 28)", st["sigma_current_ma"], "mA"),
        (f"{at}σ̂(L̂ᴵ) (eq. 30)", st["predicted_sigma_half_period_uh"]["phase_1"], "µH"),
        (f"{at}σ̂(L̂ᴵᴵ) (eq. 30)", st["predicted_sigma_half_period_uh"]["phase_2"], "µH"),
        (f"{at}straight-ramp σ(L̂ᴵ)", ramp[0] * 1e6, "µH"),
        (f"{at}straight-ramp σ(L̂ᴵᴵ)", ramp[1] * 1e6, "µH"),
        (f"{at}σ̂(L̄) (eq. 31)", st["predicted_sigma_inductance_uh"], "µH"),
        (f"{at}σ̂(ŝ) (eq. 32)", st["predicted_sigma_position_um"], "µm"),
    ]


class SelfSensing(Exercise):
    name = "self_sensing"
    title = "Self-sensing: the gap from the PWM current ripple"
    worksheet = "self_sensing.md"
    parameters = PARAMETERS
    default_duration_s = 1.3       # one cycle 4 → 6 → 4 mm with 0.35 s holds and 0.3 s moves
    no_feedback_loop = (
        "The gap follows a prescribed trajectory (the ball is moved, not levitated): there is no "
        "position loop for ISO 14839-3 to grade.  The per-period duty rule sets the next period's "
        "flux from the model and the present flux (a one-period dead-beat, S = 1 − z⁻¹ whatever the "
        "settings), so its margins would say nothing about the estimator.")
    key_readouts = ("At 4 mm: L̂ᴵ error", "At 4 mm: L̂ᴵᴵ error", "At 4 mm: L̄/L", "At 4 mm: position bias",
                    "At 4 mm: σ̂(L̄) (eq. 31)")
    charts = (
        Chart("Inductance", "mH", (
            Series("L̄ (eq. 18)", "inductance_mean_h", 1e3, "#d62728"),
            Series("L̂ᴵ", "inductance_1_h", 1e3, "#ff7f0e"),
            Series("L̂ᴵᴵ", "inductance_2_h", 1e3, "#2ca02c"),
            Series("true L", "inductance_true_h", 1e3, "#000000")),
            band=("inductance_mean_h", "sigma_inductance_mean_h")),
        Chart("Gap", "mm", (
            Series("estimated ŝ", "gap_shown_m", 1e3, "#d62728"),
            Series("true s", "gap_true_m", 1e3, "#000000"),
            Series("reference r (levitated)", "gap_reference_m", 1e3, "#7f7f7f")),
              band=("gap_shown_m", "sigma_gap_shown_m")),
        Chart("Gap error ŝ − s ±3σ̂", "µm", (Series("ŝ − s", "gap_error_m", 1e6, "#d62728"),),
              band=("zero", "sigma_gap_shown_m")),
        Chart("Gains from L̄ (eq. 22, Fig. 2): μ̂ = L̄_m/L, η̂ = L/L̄_m", "1", (
            Series("μ̂ = L̄_m/L", "inductance_ratio", 1.0, "#d62728"),
            Series("η̂ = L/L̄_m", "voltage_gain_estimate", 1.0, "#1f77b4"),
            Series("set μ/η", "gain_ratio_set", 1.0, "#7f7f7f"))),
        Chart("Predicted spread σ̂(L̂)", "µH", (
            Series("σ̂(L̄)", "sigma_inductance_mean_h", 1e6, "#d62728"),
            Series("σ̂(L̂ᴵ)", "sigma_inductance_1_h", 1e6, "#ff7f0e"),
            Series("σ̂(L̂ᴵᴵ)", "sigma_inductance_2_h", 1e6, "#2ca02c"))),
        Chart("Residual spread σ̂(i) (eq. 28)", "mA", (
            Series("σ̂(iᴵ)", "sigma_current_1_a", 1e3, "#ff7f0e"),
            Series("σ̂(iᴵᴵ)", "sigma_current_2_a", 1e3, "#2ca02c"))),
    )

    def model(self, values: dict) -> dict:
        s = setup(values)
        gaps = np.array([s.gap_1_m, s.gap_2_m])
        return {"plant": "paper 001 eq. 1-4 with the lab's parameter set (plants.self_sensing_ball)",
                "estimator": "eq. 7 (with − R̂ i), 9-10, 18 (denominator with īᴵᴵ), 28 (M − d), 29-32",
                "constants": {"turns": s.rig.turns, "relative_permeability": s.rig.relative_permeability,
                              "core_reluctance_per_h": s.rig.core_reluctance_per_h,
                              "ball_reluctance_per_h": s.rig.ball_reluctance_per_h,
                              "leakage_reluctance_per_h": s.rig.leakage_reluctance_per_h,
                              "gap_reluctance_slope_per_h_m": s.rig.gap_reluctance_slope_per_h_m,
                              "coil_resistance_ohm": s.rig.coil_resistance_ohm, "ball_mass_kg": s.rig.ball_mass_kg},
                "sample_time_s": s.sample_time_s, "samples_per_period": s.samples_per_period,
                "pwm_period_s": s.period_s, "gaps_m": gaps.tolist(),
                "inductance_h": s.rig.inductance_h(gaps).tolist(),
                "equilibrium_current_a": s.rig.equilibrium_current_a(gaps).tolist()}

    def pole_categories(self, values: dict) -> dict[str, PoleCategory]:
        """Each gap's coil pole −R/L (its set named after the gap) is the plant's."""
        s = setup(values)
        return {coil_pole_set(gap_m): PoleCategory.PLANT for gap_m in (s.gap_1_m, s.gap_2_m)}

    def analyse_panel(self, values: dict, panel: str) -> Analysis:
        """The Scope: the figures held at gap 1 (one stationary run); the Pole map: each gap's coil
        pole; the Analysis tab: the figures at gap 2, the geometry's trade-off, the levitated loop's
        figures and the plots."""
        s = setup(values)
        if panel == SCOPE:
            notes = [(f"Readouts from {HELD_PERIODS} PWM periods held at each gap with the current settings; the histogram "
                      "is from those at gap 1. *Run Monte-Carlo* (controls, left) checks σ̂(L̄) over "
                      f"{MONTE_CARLO_SEEDS} seeds × {MONTE_CARLO_PERIODS} periods.")]
            return Analysis(held_readouts(values, s, "gap_1"), {}, notes)
        if panel == POLE_MAP:
            return Analysis([], {coil_pole_set(gap_m): np.array(
                [-s.rig.coil_resistance_ohm / float(s.rig.inductance_h(gap_m))], dtype=complex)
                for gap_m in (s.gap_1_m, s.gap_2_m)})
        readouts = held_readouts(values, s, "gap_2")
        quick = held_rows(values, "gap_1")
        extra, notes, plots = geometry.analysis(s)
        readouts += extra
        if levitation.levitated(values):
            extra, more_notes, more_plots = levitation.analysis(
                s, values, statistics(quick)["predicted_sigma_position_um"] * 1e-6)
            readouts += extra
            notes += more_notes
            plots = more_plots + plots
        return Analysis(readouts, {}, notes, plots + self.ripple_plots(values) + [histogram(
            (quick[:, COLUMN["inductance_mean_h"]] - quick[:, COLUMN["inductance_true_h"]])
            / quick[:, COLUMN["sigma_inductance_mean_h"]], f"{s.gap_1_m * 1e3:g} mm ({HELD_PERIODS} periods)")])

    def ripple_plots(self, values: dict) -> list[Plot]:
        """Two PWM periods at gap 1 after the duty has settled (the Analysis tab's snapshot of the
        current settings; the Scope tab shows the running simulation's newest periods live)."""
        s = fixed(values, "gap_1")
        loop = SelfSensingLoop(s, seed=int(values["seed"]))
        loop.run(SETTLE_PERIODS)
        rows, raw = loop.run(RIPPLE_PERIODS, raw_samples=RIPPLE_PERIODS * s.samples_per_period)
        return ripple_plots(s, raw, rows[:, COLUMN["duty"]],
                            f"Ripple of two PWM periods at {s.gap_1_m * 1e3:g} mm: fitted lines over the windows "
                            "(eq. 9-10)")

    def live_plots(self, simulation: SelfSensingSimulation) -> list[Plot]:
        """The ripple zoom of the running simulation: its newest two PWM periods."""
        raw, duties = simulation.ripple
        s = simulation.loop.setup
        step = -(-RIPPLE_PERIODS * s.samples_per_period // LIVE_RIPPLE_POINTS)
        every = f"every {step}{'nd' if step == 2 else 'th'} sample" if step > 1 else "every sample"
        return ripple_plots(s, raw, duties, f"Ripple zoom, live: the newest two PWM periods ({every}; "
                            "shaded: the LS windows, eq. 9-10)", points=LIVE_RIPPLE_POINTS)

    actions = (Action("Run Monte-Carlo", "monte_carlo",
                      f"{MONTE_CARLO_SEEDS} seeds × {MONTE_CARLO_PERIODS} PWM periods held at one gap (gap 2 when "
                      "the ball is fixed there, else gap 1) with the current settings: does the spread of L̄ − L "
                      "match the predicted σ̂(L̄) of eq. 31, and does ±3σ̂ hold 99.7 %?"),)

    def monte_carlo(self, values: dict, seeds: int = MONTE_CARLO_SEEDS, periods: int = MONTE_CARLO_PERIODS):
        """A Monte-Carlo check of eq. 31 at one fixed gap (§5, Fig. 6): the empirical std of L̄ − L over
        ``seeds`` × ``periods`` PWM periods against the mean predicted σ̂(L̄), the share inside ±3σ̂ and the
        histogram of (L̄ − L)/σ̂ against N(0, 1).  Yields the figures after every seed (progress)."""
        gap = "gap_2" if values["trajectory"] == TRAJECTORIES[2] else "gap_1"
        yield from monte_carlo_views(lambda k: stationary(values, gap, periods=periods, seed_offset=1000 + k),
                                     seeds, periods, values[f"{gap}_mm"],
                                     values["sigma_current_ma"] > 0 or values["sigma_voltage_mv"] > 0)

    def open_loops(self, values: dict) -> dict:
        """With feedback on ŝ: the position loop at gap 1, broken at the current command."""
        return levitation.open_loops(setup(values), values)

    def simulation(self, values: dict) -> SelfSensingSimulation:
        return SelfSensingSimulation(values)

    def scene(self, values: dict) -> SelfSensingScene:
        """Core, coil and the ball at its true gap; the estimate (error magnified) as an outline."""
        return SelfSensingScene({"gap": "gap_true_m", "estimate": "gap_shown_m", "sigma": "sigma_gap_shown_m",
                                 "current": "current_mean_true_a", "inductance": "inductance_true_h",
                                 "estimated_inductance": "inductance_mean_h"})

    def retune(self, simulation: SelfSensingSimulation, values: dict) -> SelfSensingSimulation:
        """Keep the ball's motion, the coil's flux and the noise stream across slider moves;
        a new PWM period length starts afresh."""
        new = setup(values)
        old = simulation.loop
        if (new.samples_per_period != old.setup.samples_per_period or new.sample_time_s != old.setup.sample_time_s
                or levitation.levitated(values) != isinstance(old, LevitatedLoop)
                or isinstance(old, LevitatedLoop) and old.control != levitation.loop_control(values)):
            return self.simulation(values)
        carried = SelfSensingSimulation(values, old.retuned(new))
        carried.ripple = simulation.ripple
        return carried

    def report_figures(self, values: dict) -> list:
        """The estimated inductance and gap through one 4 → 6 → 4 mm cycle (§3.1-3.2), and the two
        PWM periods' ripple with the fitted lines behind L̂ᴵ and L̂ᴵᴵ (eq. 11-18)."""
        from lab_modules.exercises._figures import analysis_plots, plot_figure, scope_figure
        return [scope_figure(self, [("", values)], self.default_duration_s, "One cycle 4 → 6 → 4 mm: "
                             "inductance and gap, estimated against true", charts=("Inductance", "Gap")),
                *(plot_figure(plot) for plot in analysis_plots(self, values, ("Ripple of two PWM periods",)))]

    def live_readouts(self, trace: dict[str, np.ndarray]) -> list[tuple[str, float, str]]:
        return live_readouts(trace, LAST_PERIODS)

    def metrics(self, values: dict, duration_s: float) -> dict:
        s = setup(values)
        gaps = np.array([s.gap_1_m, s.gap_2_m])
        result = {
            "inductance_mh": dict(zip(GAPS, (s.rig.inductance_h(gaps) * 1e3).tolist())),
            "equilibrium_current_a": dict(zip(GAPS, s.rig.equilibrium_current_a(gaps).tolist())),
        }
        per_gap = {}
        for gap in GAPS:
            reference = stationary(values, gap, periods=QUIET_PERIODS, **IDEAL)
            per_gap[gap] = statistics(stationary(values, gap), reference)
        for key in ("half_period_error_percent", "max_relative_error", "inductance_ratio", "position_bias_um",
                    "position_error_max_um", "predicted_sigma_half_period_uh", "predicted_sigma_inductance_uh",
                    "predicted_sigma_position_um", "empirical_sigma_inductance_uh", "monte_carlo_to_predicted_ratio",
                    "within_3sigma_percent", "shift_vs_ideal_uh", "weights", "delta_current_ma", "duty"):
            result[key] = {gap: per_gap[gap][key] for gap in GAPS}
        result["position_error_max_um"]["max"] = max(result["position_error_max_um"][g] for g in GAPS)
        result["max_relative_error"]["max"] = max(v for g in GAPS for v in per_gap[g]["max_relative_error"].values())
        result["mean_shift_vs_ideal_uh_max"] = max(abs(per_gap[g]["shift_vs_ideal_uh"]["mean"]) for g in GAPS)
        result["stationary_periods_per_gap"] = per_gap["gap_1"]["periods"]
        sigmas = [per_gap[g]["sigma_current_ma"] for g in GAPS]
        result["sigma_current_ma"] = float(np.mean(sigmas))
        if s.sigma_voltage_v > 0 and s.sigma_current_a > 0:
            alone = statistics(stationary(values, "gap_1", periods=2000, sigma_current_a=0.0))
            result["voltage_noise_share_percent"] = (alone["empirical_sigma_inductance_uh"]
                                                     / per_gap["gap_1"]["empirical_sigma_inductance_uh"] * 100)
        # the run over the prescribed trajectory
        simulation = SelfSensingSimulation(values)
        n_periods = max(round(duration_s / simulation.sample_time_s), 1)
        rows = simulation.advance(n_periods)[:, 1:]
        result["trajectory"] = trajectory_statistics(rows)
        if (s.voltage_offset_v or s.current_offset_a) and s.trajectory == TRAJECTORIES[0]:
            ideal = SelfSensingSimulation({**values, "voltage_offset_v": 0.0, "current_offset_ma": 0.0})
            ideal_rows = ideal.advance(n_periods)[:, 1:]
            predicted = eq25_shift_h(ideal_rows, s.voltage_offset_v, s.current_offset_a,
                                     s.rig.coil_resistance_ohm, s.samples_per_period, s.trim_samples,
                                     s.sample_time_s)
            result["trajectory"]["offset"] = moving_offset_shift(rows, ideal_rows, predicted)
        if levitation.levitated(values):
            result["levitation"] = levitation.metrics(setup(values), values, duration_s)
        result["geometry"] = geometry.metrics(s)
        if s.sigma_current_a > 0:
            result["geometry"]["simulated_to_straight_ramp"] = (per_gap["gap_1"]["predicted_sigma_position_um"]
                                                                / result["geometry"]["straight_ramp_sigma_gap_um"])
        result["realtime_factor"] = simulation.realtime_factor()
        result["duration_s"] = n_periods * simulation.sample_time_s
        result["status"] = "ok"
        return result


EXERCISE = SelfSensing()

QUIET = {"sigma_current_ma": 0.0, "sigma_voltage_mv": 0.0}
FIXED_4 = {**QUIET, "trajectory": TRAJECTORIES[1]}


LEVITATED = {"feedback": levitation.FEEDBACK[1], "trajectory": TRAJECTORIES[1]}
#: Half the sensor noise: the duty stays clear of its limits and the loop on ŝ is linear.
HALF_NOISE_LEVITATED = {**LEVITATED, "sigma_current_ma": 0.5, "sigma_voltage_mv": 7.5}
LEVITATION_RUN_S = 5.0         # one run's true-gap std to ±3.9 % (the closed loop's autocorrelation, Bartlett)


def _within(value: float, relative: float) -> tuple[float, float]:
    low, high = sorted((value * (1 - relative), value * (1 + relative)))
    return (round(low, 6), round(high, 6))


EXERCISE.claims = (
    Claim("lab parameter set (paper 001 eq. 1-2)", "inductance at 4 mm", "not given (31.466 mH with the "
          "lab's set)", "inductance_mh.gap_1", _within(31.466, 1e-4), "mH",
          "eq. 2 with N = 600, μr = 2000 and the geometry of plants.self_sensing_ball", settings=QUIET),
    Claim("lab parameter set (paper 001 eq. 1-2)", "inductance at 6 mm", "not given (28.901 mH)",
          "inductance_mh.gap_2", _within(28.901, 1e-4), "mH", settings=QUIET),
    Claim("paper 001 §4.2 (ī = 1.5 A)", "equilibrium current at 4 mm", "mean of both: ī = 1.5 A",
          "equilibrium_current_a.gap_1", (1.194, 1.198), "A", "½ i² |∂L/∂s| = m g", settings=QUIET),
    Claim("paper 001 §4.2 (ī = 1.5 A)", "equilibrium current at 6 mm", "mean of both: ī = 1.5 A",
          "equilibrium_current_a.gap_2", (1.789, 1.793), "A", settings=QUIET),
    Claim("paper 001 §3.1", "largest relative error of L̂ᴵ, L̂ᴵᴵ and L̄ at rest, R̂ = R, both gaps",
          "identical and exact", "max_relative_error.max", (0.0, 2e-4), "",
          "noise free; what is left is the curvature of the exponential current ramp", settings=QUIET),
    Claim("paper 001 §3.1, eq. 2", "largest position error at rest, both gaps", "exact",
          "position_error_max_um.max", (0.0, 5.0), "µm", settings=QUIET),
    Claim("paper 001 §3.2, eq. 17-18", "largest relative error of L̄ during the 4 ↔ 6 mm moves (0.3 s)",
          "motion eliminated (approximately)", "trajectory.mean_max_relative_error", (0.0, 5e-4), "",
          "against the period's mean true inductance", settings=QUIET),
    Claim("paper 001 §3.2, eq. 17", "largest relative error of L̂ᴵ during the moves",
          "L̂ᴵ = L̄ᴵ + L̇ īᴵ Δtᴵ/Δiᴵ", "trajectory.phase_1_max_relative_error", (2.4e-3, 3.6e-3), "",
          "against the mean true inductance over the phase-I window; minimum-jerk moves", settings=QUIET),
    Claim("paper 001 §3.2, eq. 11-17", "L̂ᴵ error with R̂ = 0.8 R at 4 mm", "ΔR īᴵ Δtᴵ/Δiᴵ",
          "half_period_error_percent.gap_1.phase_1", (6.82, 7.42), "%", settings={**QUIET, "resistance_ratio": 0.8}),
    Claim("paper 001 §3.2, eq. 11-17", "L̂ᴵᴵ error with R̂ = 0.8 R at 4 mm", "opposite sign to L̂ᴵ's",
          "half_period_error_percent.gap_1.phase_2", (-4.45, -3.85), "%",
          settings={**QUIET, "resistance_ratio": 0.8}),
    Claim("paper 001 §3.2, eq. 18", "L̄ error with R̂ = 0.8 R at 4 mm", "resistance error eliminated",
          "half_period_error_percent.gap_1.mean", (-0.02, 0.02), "%", settings={**QUIET, "resistance_ratio": 0.8}),
    Claim("paper 001 eq. 7 (misprint)", "L̂ᴵ error with the printed v_j + R i_j at 4 mm",
          "(printed formula)", "half_period_error_percent.gap_1.phase_1", (20.0, None), "%",
          "the printed sign makes each half-period estimate wrong by tens of per cent ...",
          settings={**QUIET, "equation_7": "v + R i (printed)"}),
    Claim("paper 001 eq. 7 (misprint)", "L̄ error with the printed v_j + R i_j at 4 mm", "(printed formula)",
          "half_period_error_percent.gap_1.mean", (-0.02, 0.02), "%",
          "... and hides in the average, as a resistance error does", settings={**QUIET, "equation_7": "v + R i (printed)"}),
    Claim("paper 001 §4.1, eq. 22, Fig. 2", "L̄_m/L̄ with μ = 1.05 at 4 mm", "μ̂ = 1.05 exactly",
          "inductance_ratio.gap_1", (1.0499, 1.0501), "", settings={**QUIET, "current_gain": 1.05}),
    Claim("paper 001 §4.1, eq. 22", "position bias with μ = 1.05 at 4 mm", "not given (multiplicative error)",
          "position_bias_um.gap_1", _within(-680.0, 0.02), "µm", settings={**QUIET, "current_gain": 1.05}),
    Claim("paper 001 §4.1, eq. 22", "position bias with μ = 1.05 at 6 mm", "not given",
          "position_bias_um.gap_2", _within(-1318.0, 0.02), "µm", settings={**QUIET, "current_gain": 1.05}),
    Claim("paper 001 §4.1, eq. 22, Fig. 2", "L̄_m/L̄ with η = 1.05 at 4 mm", "1/η̂ = 1/1.05 exactly",
          "inductance_ratio.gap_1", (0.952281, 0.952481), "", settings={**QUIET, "voltage_gain": 1.05}),
    Claim("paper 001 §4.2, eq. 24", "L̂ᴵ shift with Δv = 0.05 v_bat = 0.57 V at 4 mm", "Δtᴵ/Δiᴵ Δv",
          "shift_vs_ideal_uh.gap_1.phase_1", _within(-2133.0, 0.03), "µH",
          settings={**QUIET, "voltage_offset_v": 0.57}),
    Claim("paper 001 §4.2, eq. 25, Fig. 3", "largest L̄ shift with Δv = 0.57 V, both gaps", "vanishingly small",
          "mean_shift_vs_ideal_uh_max", (0.0, 2.0), "µH", settings={**QUIET, "voltage_offset_v": 0.57}),
    Claim("paper 001 §4.2, eq. 25, Fig. 3", "largest L̄ shift with Δi = 0.05 ī = 75 mA, both gaps",
          "vanishingly small", "mean_shift_vs_ideal_uh_max", (0.0, 1.0), "µH",
          settings={**QUIET, "current_offset_ma": 75.0}),
    Claim("paper 001 §4.2, eq. 25, Fig. 3", "largest L̄ shift with Δv = 0.57 V during the 4 ↔ 6 mm moves",
          "vanishingly small", "trajectory.offset.shift_max_uh", (0.0, 2.5), "µH",
          "against the same run without the offset; 6·10⁻⁵ of L", settings={**QUIET, "voltage_offset_v": 0.57}),
    Claim("paper 001 §4.2, eq. 25", "that shift / eq. 25 (Δt, Δi, ī of the run), Δv = 0.57 V, moving",
          "eq. 25", "trajectory.offset.shift_to_eq25", (0.9, 1.1), "",
          "at the period of the largest shift: the moves make īᴵᴵ − īᴵ ≠ 0", settings={**QUIET, "voltage_offset_v": 0.57}),
    Claim("paper 001 §4.2, eq. 25, Fig. 3", "largest L̄ shift with Δi = 75 mA during the moves",
          "vanishingly small", "trajectory.offset.shift_max_uh", (0.0, 1.0), "µH",
          settings={**QUIET, "current_offset_ma": 75.0}),
    Claim("paper 001 §4.2, eq. 25", "that shift / eq. 25, Δi = 75 mA, moving", "eq. 25",
          "trajectory.offset.shift_to_eq25", (0.9, 1.1), "", settings={**QUIET, "current_offset_ma": 75.0}),
    Claim("paper 001 §5, eq. 28, Fig. 4", "mean σ̂(i) with σ(i) = 1 mA, σ(v) = 15 mV", "matches 1 mA",
          "sigma_current_ma", (0.98, 1.02), "mA", "both phases, both gaps, 5000 periods each"),
    Claim("paper 001 §5, eq. 30, Fig. 5", "σ̂(L̂ᴵ) at 4 mm", "not given (lab: 25.7 µH)",
          "predicted_sigma_half_period_uh.gap_1.phase_1", _within(25.7, 0.03), "µH"),
    Claim("paper 001 §5, eq. 30, Fig. 5", "σ̂(L̂ᴵᴵ) at 4 mm", "not given (lab: 34.5 µH)",
          "predicted_sigma_half_period_uh.gap_1.phase_2", _within(34.5, 0.03), "µH"),
    Claim("paper 001 §5, eq. 31, Fig. 6", "σ̂(L̄) at 4 mm", "not given (lab: 23.7 µH)",
          "predicted_sigma_inductance_uh.gap_1", _within(23.7, 0.03), "µH"),
    Claim("paper 001 §5, eq. 32, Fig. 7", "σ̂(ŝ) at 4 mm", "not given (lab: 12.35 µm)",
          "predicted_sigma_position_um.gap_1", _within(12.35, 0.03), "µm"),
    Claim("paper 001 §5, eq. 30, Fig. 5", "σ̂(L̂ᴵ) at 6 mm", "not given (lab: 22.65 µH)",
          "predicted_sigma_half_period_uh.gap_2.phase_1", _within(22.65, 0.03), "µH"),
    Claim("paper 001 §5, eq. 30, Fig. 5", "σ̂(L̂ᴵᴵ) at 6 mm", "not given (lab: 35.8 µH)",
          "predicted_sigma_half_period_uh.gap_2.phase_2", _within(35.8, 0.03), "µH"),
    Claim("paper 001 §5, eq. 31, Fig. 6", "σ̂(L̄) at 6 mm", "not given (lab: 25.8 µH)",
          "predicted_sigma_inductance_uh.gap_2", _within(25.8, 0.03), "µH"),
    Claim("paper 001 §5, eq. 32, Fig. 7", "σ̂(ŝ) at 6 mm", "not given (lab: 30.2 µm)",
          "predicted_sigma_position_um.gap_2", _within(30.2, 0.03), "µm"),
    Claim("paper 001 §5, Fig. 6", "Monte-Carlo std of L̄ − L / predicted σ̂(L̄) at 4 mm",
          "confidence bands predicted accurately", "monte_carlo_to_predicted_ratio.gap_1", (0.95, 1.05), "",
          "5000 periods"),
    Claim("paper 001 §5, Fig. 6", "Monte-Carlo std of L̄ − L / predicted σ̂(L̄) at 6 mm",
          "confidence bands predicted accurately", "monte_carlo_to_predicted_ratio.gap_2", (0.95, 1.05), ""),
    Claim("paper 001 §5, Fig. 6-7", "L̄ − L inside ±3σ̂(L̄) at 4 mm", "99.7 % (theory)",
          "within_3sigma_percent.gap_1", (99.5, None), "%", "5000 periods"),
    Claim("paper 001 §5, Fig. 6-7", "L̄ − L inside ±3σ̂(L̄) at 6 mm", "99.7 % (theory)",
          "within_3sigma_percent.gap_2", (99.5, None), "%", "5000 periods"),
    Claim("paper 001 §5 (errors-in-variables neglected)", "std of L̄ from voltage noise alone / with both",
          "Δψ̃ treated as deterministic", "voltage_noise_share_percent", (0.0, 10.0), "%", "4 mm, 2000 periods"),
    Claim("paper 001 §5 (conclusion after eq. 32)", "σ̂(ŝ) at 4 mm with T_a = 0.5 µs, T_pwm fixed",
          "smaller for more samples and smaller T_s", "predicted_sigma_position_um.gap_1", _within(8.76, 0.03),
          "µm", "twice the samples: σ falls by √2", settings={"sample_time_us": "0.5"}),
    Claim("paper 001 §5 (conclusion after eq. 32)", "σ̂(ŝ) at 4 mm with T_a = 0.5 µs, T_pwm = 1024 T_a",
          "smaller for more samples and smaller T_s", "predicted_sigma_position_um.gap_1", _within(24.7, 0.03),
          "µm", "half the period: the same samples over half the ramp, σ doubles",
          settings={"sample_time_us": "0.5", "pwm_mode": PWM_MODES[1]}),
    Claim("paper 001 after eq. 32 (design trade-off)", "σ̂(ŝ) at 4 mm with N = 900 turns (600 set)",
          "large L: slow current", "predicted_sigma_position_um.gap_1", _within(24.78, 0.03), "µm",
          "L/R grows 2.25× (12.6 → 28.3 ms) and, at the same σ(i), σ(ŝ) ∝ N² (σ(L̂) ∝ L²)",
          settings={"turns": 900}),
    Claim("paper 001 after eq. 32", "σ̂(ŝ) at 4 mm with A_s = 0.35 cm² (∂R_s/∂s doubled)",
          "large ∂R_s/∂s: small σ(ŝ)", "predicted_sigma_position_um.gap_1", _within(23.2, 0.03), "µm",
          "with the lab's leakage (R_s = 3 R_l at 4 mm) a larger ∂R_s/∂s diverts flux into the leakage path, "
          "|∂L/∂s| falls and σ(ŝ) nearly doubles; eq. 32's factor alone holds L̄ fixed", deviation=True,
          settings={"gap_area_cm2": 0.35}),
    Claim("paper 001 after eq. 32", "σ̂(ŝ) at 4 mm with R_l = 6·10⁷ H⁻¹ (less leakage)", "not given",
          "predicted_sigma_position_um.gap_1", _within(2.34, 0.03), "µm",
          "5× smaller and a 2.3× faster coil: leakage costs both", settings={"leakage_reluctance": 6e7}),
    Claim("lab (eq. 28-32 for straight ramps)", "simulated σ̂(ŝ) / straight-ramp σ(ŝ), A_s = 0.35 cm²",
          "not given", "geometry.simulated_to_straight_ramp", (0.97, 1.03), "",
          "the trade-off plots use the straight-ramp formula", settings={"gap_area_cm2": 0.35}),
    Claim("lab target (paper 001's sensorless bearing, loop closed on ŝ)", "ball held at 4 mm on ŝ alone, "
          "f_c = 6 Hz, σ(i) = 1 mA, σ(v) = 15 mV", "not given (the paper estimates, it does not levitate)",
          "levitation.held_s_least", (LEVITATION_RUN_S - 0.01, None), "s",
          "the whole run without leaving the reference by 1 mm, each of 8 seeds", settings=LEVITATED,
          duration_s=LEVITATION_RUN_S),
    Claim("lab target (loop on ŝ)", "true-gap std / prediction from the estimate's spread through the linear loop, "
          "mean of 8 seeds", "lab target: within 20 %", "levitation.gap_std_to_predicted_mean", (1.09, 1.27), "",
          "18 % above the prediction: the noise drives the duty to its limit 0.8 (each phase ≥ 20 % of T), which "
          "the linear loop lacks; its σ(χ) = 0.073 puts the limit 2.3σ above χ_eq = 0.63, the duty sits there in "
          "0.8 % of periods and each clipped period leaves the current short, always the same way. Band: ±5 "
          "standard errors (0.017) of the mean", deviation=True, settings=LEVITATED, duration_s=LEVITATION_RUN_S),
    Claim("lab target (loop on ŝ)", "duty std / the linear loop's prediction from the estimate's spread, mean of 8 "
          "seeds", "not given", "levitation.duty_std_to_predicted_mean", (0.95, 1.05), "",
          "the duty's swing that reaches the limit is the linear loop's own", settings=LEVITATED,
          duration_s=LEVITATION_RUN_S),
    Claim("lab target (loop on ŝ)", "true-gap std / prediction, σ(i) = 0.5 mA, σ(v) = 7.5 mV, mean of 8 seeds",
          "lab target: within 20 %", "levitation.gap_std_to_predicted_mean", (0.94, 1.06), "",
          "the duty stays 5σ clear of its limit: the linear prediction holds; band ±4 standard errors of the mean "
          "(one 4.9 s run's std: ±3.9 % from the loop's autocorrelation)", settings=HALF_NOISE_LEVITATED,
          duration_s=LEVITATION_RUN_S),
    Claim("lab target (loop on ŝ)", "share of periods with the duty at its limit, σ(i) = 0.5 mA, σ(v) = 7.5 mV",
          "not given", "levitation.duty_at_limit_percent_mean", (0.0, 0.01), "%", "8 seeds",
          settings=HALF_NOISE_LEVITATED, duration_s=LEVITATION_RUN_S),
    Claim("lab target (loop on ŝ)", "true-gap std / prediction from the estimator's own σ̂(ŝ) (eq. 32), mean of 8 "
          "seeds", "not given", "levitation.gap_std_to_eq32_prediction_mean", (0.8, 1.35), "",
          "wider than the rows above: in the loop the spread of ŝ − s exceeds the mean σ̂(ŝ) by about 4 % (σ̂ grows "
          "with the duty), besides the duty's limit", settings=LEVITATED, duration_s=LEVITATION_RUN_S),
    Claim("lab target (loop on ŝ)", "largest f_c a noise-free run holds / the analysis's stability limit",
          "not given (lab: limit 23.2 Hz at 4 mm)", "levitation.nonlinear_limit_to_predicted", (0.9, 1.1), "",
          "bisection of 1 s runs between 0.8 and 1.2 × the limit; the limit from the loop with ŝ one period "
          "old, averaged over it and the switching instant moved", settings=LEVITATED),
    Claim("lab target (loop on ŝ)", "a run at 1.1 × the predicted limit stops with its message", "not given",
          "levitation.stops_at_1_1_limit", (1.0, 1.0), "", "noise free, 1 s", settings=LEVITATED),
)
