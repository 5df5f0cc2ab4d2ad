"""self_sensing's coil and gap geometry: controls for N, A_s and R_l (eq. 1-2), and the design
trade-off after eq. 32 (a small σ(ŝ) against a fast coil) from the straight-ramp variance.

For straight ramps of slope v/L in both phases (v = v_bat ∓ R i_eq, M samples per window),
eq. 28-30 give σ(L̂) = L² σ(i) / (T_a v √((M³ − M)/12)); the weights of eq. 18 become
wᴵ = (v_bat − R i)/(2 v_bat), wᴵᴵ = (v_bat + R i)/(2 v_bat) (Δi Δt of the other phase), eq. 31
σ²(L̄) = wᴵ² σ²(L̂ᴵ) + wᴵᴵ² σ²(L̂ᴵᴵ), and eq. 32 σ(ŝ) = |∂s/∂L| σ(L̄).  At the lab's parameter set this
is within 0.1 % of the simulation's mean σ̂(ŝ).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from lab_modules.estimators.ripple_inductance import predicted_sigma_inductance_h
from lab_modules.exercises import Plot
from lab_modules.loops.self_sensing_loop import SelfSensingSetup
from lab_modules.parameters import Parameter, in_si
from lab_modules.plants.self_sensing_ball import RIG, SelfSensingBall

SWEEP_FACTORS = np.geomspace(0.5, 2.0, 25)     # each geometry value scaled by these in the trade-off plots
SWEPT = (("turns", "N", "#1f77b4"), ("gap_area_m2", "A_s", "#d62728"),
         ("leakage_reluctance_per_h", "R_l", "#2ca02c"))

P = Parameter
PARAMETERS = (
    P("turns", "Turns N", "", 600, 400, 1200,
      "Coil turns (eq. 2: L = N²/R). The lab's set: 600. More turns: less current for the weight, a slower "
      "coil (L ∝ N²) and, at the same current noise, a larger σ(ŝ).", integer=True, step=10, group="Geometry"),
    P("gap_area_cm2", "Gap area A_s", "cm²", 0.7, 0.35, 2.8,
      "Effective area of the air gap (eq. 1: ∂R_s/∂s = 1/(μ0 A_s)). The lab's set: 0.70 cm². A small A_s "
      "needs more current: past the bridge's duty limits the ball is not carried.", log=True, step=0.01,
      group="Geometry"),
    P("leakage_reluctance", "Leakage reluctance R_l", "1/H", RIG.leakage_reluctance_per_h, 5e6, 1e9,
      "Reluctance of the leakage path parallel to gap and ball (eq. 1-2). The lab's set: 1.5·10⁷ H⁻¹; "
      "a large R_l (little leakage) sends the flux through the gap.", log=True, group="Geometry"),
)


def rig(values: dict) -> SelfSensingBall:
    """The rig of the parameter values (the lab's set with N, A_s and R_l of the controls)."""
    si = in_si(PARAMETERS, values)
    return replace(RIG, turns=float(values["turns"]), gap_area_m2=si["gap_area_cm2"],
                   leakage_reluctance_per_h=float(values["leakage_reluctance"]))


def straight_ramp_sigma_gap_m(ball: SelfSensingBall, gap_m: float, setup: SelfSensingSetup) -> float:
    """σ(ŝ) [m] at a gap [m] for straight ramps at the equilibrium current (eq. 28-32, module
    docstring), with the set-up's σ(i), v_bat, T_a, period and window trim."""
    current = float(ball.equilibrium_current_a(gap_m))
    inductance = float(ball.inductance_h(gap_m))
    v_bat = setup.battery_voltage_v or ball.battery_voltage_v
    n = setup.samples_per_period
    on = round(0.5 * (1.0 + ball.coil_resistance_ohm * current / v_bat) * n)     # χ = ½(1 + R i/v_bat)
    ramps = (v_bat - ball.coil_resistance_ohm * current, v_bat + ball.coil_resistance_ohm * current)
    samples = (on - 2 * setup.trim_samples + 1, n - on - 2 * setup.trim_samples + 1)
    sigma = [predicted_sigma_inductance_h(inductance, setup.sigma_current_a, v, m, setup.sample_time_s)
             for v, m in zip(ramps, samples)]
    sigma_mean = np.hypot(ramps[0] * sigma[0], ramps[1] * sigma[1]) / (2 * v_bat)   # eq. 31
    return float(ball.position_sensitivity_m_per_h(inductance) * sigma_mean)          # eq. 32


def coil_time_constant_s(ball: SelfSensingBall, gap_m: float) -> float:
    """τ = L(s)/R [s]: how fast the coil current (and the force) can follow."""
    return float(ball.inductance_h(gap_m)) / ball.coil_resistance_ohm


def analysis(setup: SelfSensingSetup) -> tuple[list, list, list]:
    """(readouts, notes, plots) of the trade-off at gap 1: σ(ŝ) and L/R as N, A_s, R_l are scaled."""
    gap = setup.gap_1_m
    ball = setup.rig
    sigma, tau = [], []
    for field, label, colour in SWEPT:
        scaled = [replace(ball, **{field: getattr(ball, field) * f}) for f in SWEEP_FACTORS]
        sigma.append((f"{label} × factor", np.array([straight_ramp_sigma_gap_m(b, gap, setup) for b in scaled])
                      * 1e6, colour))
        tau.append((f"{label} × factor", np.array([coil_time_constant_s(b, gap) for b in scaled]) * 1e3, colour))
    tag = f"at {gap * 1e3:g} mm"
    readouts = [
        (f"Straight-ramp σ(ŝ) {tag} (eq. 30-32)", straight_ramp_sigma_gap_m(ball, gap, setup) * 1e6, "µm"),
        (f"Coil time constant L/R {tag}", coil_time_constant_s(ball, gap) * 1e3, "ms"),
        ("Gap reluctance slope ∂R_s/∂s (eq. 1)", ball.gap_reluctance_slope_per_h_m, "1/(H·m)"),
        (f"R_s/R_l {tag}", gap * ball.gap_reluctance_slope_per_h_m / ball.leakage_reluctance_per_h, ""),
    ]
    notes = [("Design trade-off (after eq. 32): each curve scales one of N, A_s, R_l of the current settings "
              "(factor 1: as set), the others held; σ(ŝ) for straight ramps at the same σ(i), v_bat, T_a and "
              "period. While R_s ≫ R_l a larger ∂R_s/∂s (smaller A_s) sends flux into the leakage path and "
              "σ(ŝ) grows; more turns slow the coil and, at a fixed current noise, widen σ(ŝ) (∝ N²).")]
    plots = [
        Plot(f"Trade-off {tag}: σ(ŝ) when one geometry value is scaled (σ(i) = "
             f"{setup.sigma_current_a * 1e3:g} mA)", "factor on the set value [1]", "σ(ŝ) [µm]",
             SWEEP_FACTORS, tuple(sigma), log_x=True, log_y=True),
        Plot(f"Trade-off {tag}: coil time constant L/R (current and force speed)", "factor on the set value [1]",
             "L/R [ms]", SWEEP_FACTORS, tuple(tau), log_x=True, log_y=True),
    ]
    return readouts, notes, plots


def metrics(setup: SelfSensingSetup) -> dict:
    """The geometry's figures at gap 1 that the claims read."""
    gap = setup.gap_1_m
    return {"straight_ramp_sigma_gap_um": straight_ramp_sigma_gap_m(setup.rig, gap, setup) * 1e6,
            "coil_time_constant_ms": coil_time_constant_s(setup.rig, gap) * 1e3,
            "gap_reluctance_to_leakage": gap * setup.rig.gap_reluctance_slope_per_h_m
            / setup.rig.leakage_reluctance_per_h}
