"""self_sensing's levitation on the estimate: controls, the analysis of the loop on ŝ and
the metrics its claims read (``loops.self_sensing_levitation``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from lab_modules.exercises import Plot
from lab_modules.loops.self_sensing_levitation import (
    LevitatedLoop,
    LevitationControl,
    LinearLoop,
    linear_loop,
    predicted_duty_spread,
    predicted_gap_spread_m,
    shortest_phase_samples,
    spectral_radius,
    spread_relative_error,
    stable_bandwidths_rad_s,
)
from lab_modules.loops.self_sensing_loop import COLUMN, TRAJECTORIES, SelfSensingSetup
from lab_modules.parameters import Parameter, in_si

FEEDBACK = ("none: prescribed motion", "self-sensing estimate ŝ")
STOP_DEVIATION_M = 1e-3        # the run stops when the ball leaves its reference by more than this
#: Each phase keeps this share of the period: a short window's estimate is so noisy (σ ∝ M^−3/2) that
#: one bad period would throw the ball.
SHORTEST_PHASE = 0.2
SETTLE_S = 0.1                 # the start-up left out of the measured spread
SPREAD_SEEDS = 8               # runs whose mean spread ratio the claims read (one run's std: ±4 % at the defaults)
LIMIT_RUN_S = 1.0              # noise-free runs of the limit search
LIMIT_STEPS = 6                # bisection steps between 0.8 and 1.2 × the predicted limit
SWEEP_HZ = np.geomspace(0.3, 40.0, 60)

P = Parameter
PARAMETERS = (
    P("feedback", "Position feedback", "", FEEDBACK[0], choices=FEEDBACK,
      description="none: the ball is moved on the prescribed path (Fig. 2-7); ŝ: the ball levitates on its own "
                  "estimate, one PWM period old (no position sensor).", group="Levitation"),
    P("bandwidth_hz", "Controller bandwidth f_c", "Hz", 6.0, 0.5, 40.0,
      "PID on ŝ designed for a triple pole at −2π f_c (delay-free); the delay limits it (see Analysis).",
      step=0.1, group="Levitation"),
    P("derivative_ratio", "Derivative filter n_f", "", 10.0, 2.0, 40.0,
      "The derivative's low-pass corner at n_f · 2π f_c: more filtering, less noise, less phase.", step=0.5,
      group="Levitation"),
)


def levitated(values: dict) -> bool:
    """Whether the position loop is closed on ŝ."""
    return values["feedback"] == FEEDBACK[1]


def loop_control(values: dict) -> LevitationControl:
    """The loop on ŝ of the parameter values."""
    si = in_si(PARAMETERS, values)
    return LevitationControl(bandwidth_rad_s=2 * np.pi * si["bandwidth_hz"],
                             derivative_filter_ratio=float(values["derivative_ratio"]),
                             stop_deviation_m=STOP_DEVIATION_M, shortest_phase=SHORTEST_PHASE)


def open_loops(setup: SelfSensingSetup, values: dict) -> dict:
    """The loop on ŝ broken at the current command, linearised at gap 1."""
    return {f"loop on ŝ at {setup.gap_1_m * 1e3:g} mm": linear_loop(setup, loop_control(values), setup.gap_1_m)
            .open_loop} if levitated(values) else {}


def analysis(setup: SelfSensingSetup, values: dict, sigma_estimate_m: float) -> tuple[list, list, list]:
    """(readouts, notes, plots) of the loop on ŝ at gap 1: the stable range of f_c, the true-gap
    spread σ(ŝ) causes through the loop, both against f_c, and the duty's spread against its limits
    (where the linear prediction ends)."""
    control_ = loop_control(values)
    gap = setup.gap_1_m
    low, high = stable_bandwidths_rad_s(setup, control_, gap)
    loop = linear_loop(setup, control_, gap)
    radius, spread = [], []
    for hz in SWEEP_HZ:
        swept = linear_loop(setup, control_._replace(bandwidth_rad_s=2 * np.pi * hz), gap)
        radius.append(spectral_radius(swept))
        spread.append(predicted_gap_spread_m(swept, sigma_estimate_m) * 1e6)
    tag = f"at {gap * 1e3:g} mm"
    duty_spread = predicted_duty_spread(loop, sigma_estimate_m)
    shortest = shortest_duty(setup, control_)
    margin = duty_limit_margin(loop, shortest, duty_spread)
    readouts = [
        (f"Loop on ŝ {tag}: lowest stable f_c", low / (2 * np.pi), "Hz"),
        (f"Loop on ŝ {tag}: largest stable f_c", high / (2 * np.pi), "Hz"),
        (f"Loop on ŝ {tag}: closed-loop spectral radius", spectral_radius(loop), ""),
        (f"Loop on ŝ {tag}: σ(ŝ) fed back (eq. 32)", sigma_estimate_m * 1e6, "µm"),
        (f"Loop on ŝ {tag}: predicted true-gap std from σ(ŝ)", predicted_gap_spread_m(loop, sigma_estimate_m) * 1e6,
         "µm"),
        (f"Loop on ŝ {tag}: predicted duty std from σ(ŝ)", duty_spread, ""),
        (f"Loop on ŝ {tag}: duty's distance to its nearer limit, in duty stds", margin, ""),
    ]
    notes = [("Loop on ŝ: linearised at gap 1, one step per PWM period; ŝ is the mean gap over a period, read one "
              "period later; a command moves the switching instant χT, so the new current starts only there. "
              "The margins below include all three."),
             (f"Loop on ŝ: the predictions are linear; they hold while the duty (χ_eq = {loop.duty:.3f}) stays clear "
              f"of its limits {shortest:.2f} … {1 - shortest:.2f} (each phase keeps {shortest:.0%} of the period). "
              "Within about 3σ of a limit the clipped periods leave the current short and the true gap spreads "
              "more than predicted.")]
    plots = [
        Plot(f"Loop on ŝ {tag}: closed-loop spectral radius against f_c (stable below 1)", "f_c [Hz]",
             "spectral radius [1]", SWEEP_HZ, (("spectral radius", np.array(radius), "#1f77b4"),
                                               ("stability edge", np.ones(len(SWEEP_HZ)), "#7f7f7f")), log_x=True),
        Plot(f"Loop on ŝ {tag}: true-gap std caused by σ(ŝ) = {sigma_estimate_m * 1e6:.1f} µm, against f_c",
             "f_c [Hz]", "std of s [µm]", SWEEP_HZ, (("predicted std of s", np.array(spread), "#d62728"),),
             log_x=True, log_y=True),
    ]
    return readouts, notes, plots


def holds(setup: SelfSensingSetup, control_: LevitationControl, duration_s: float, seed: int) -> bool:
    """Whether the ball stays within ``STOP_DEVIATION_M`` of its reference for ``duration_s``."""
    loop = LevitatedLoop(setup, control_, seed)
    loop.run(max(round(duration_s / setup.period_s), 1))
    return not loop.stop_message


def shortest_duty(setup: SelfSensingSetup, control_: LevitationControl) -> float:
    """The duty's lower limit [-] (the upper one is 1 minus it): each phase keeps this share."""
    n = setup.samples_per_period
    return shortest_phase_samples(n, setup.trim_samples, control_.shortest_phase) / n


def duty_limit_margin(loop: LinearLoop, shortest: float, duty_spread: float) -> float:
    """How many duty stds [σ] the equilibrium duty lies from the nearer of its limits."""
    return min(loop.duty - shortest, 1.0 - shortest - loop.duty) / duty_spread


def spread_run(setup: SelfSensingSetup, control_: LevitationControl, at_reference: LinearLoop, seed: int,
               duration_s: float) -> dict:
    """One run on ŝ: how long it held, the true gap's and the estimate error's spread, the duty's
    spread and its share of periods at the limits, the spread against its linear predictions."""
    loop = LevitatedLoop(setup, control_, seed)
    rows, _ = loop.run(max(round(duration_s / setup.period_s), 1))
    settled = rows[round(SETTLE_S / setup.period_s):]
    gap = settled[:, COLUMN["gap_true_m"]]
    duty = settled[:, COLUMN["duty"]]
    sigma_estimate = float(np.mean(settled[:, COLUMN["sigma_gap_m"]])) if len(settled) else float("nan")
    estimate_error = float(np.std(settled[:, COLUMN["gap_estimated_m"]] - gap))
    shortest = shortest_duty(setup, control_)
    return {
        "held_s": len(rows) * setup.period_s,
        "stop_message": loop.stop_message,
        "gap_std_um": float(np.std(gap) * 1e6),
        "gap_mean_um": float(np.mean(gap) * 1e6),
        "sigma_estimate_um": sigma_estimate * 1e6,
        "estimate_error_std_um": estimate_error * 1e6,
        "predicted_gap_std_um": predicted_gap_spread_m(at_reference, estimate_error) * 1e6,
        "gap_std_to_predicted": float(np.std(gap)) / predicted_gap_spread_m(at_reference, estimate_error),
        "gap_std_to_eq32_prediction": float(np.std(gap)) / predicted_gap_spread_m(at_reference, sigma_estimate),
        "duty_std": float(np.std(duty)),
        "duty_std_to_predicted": float(np.std(duty)) / predicted_duty_spread(at_reference, estimate_error),
        "duty_at_limit_percent": float(np.mean((duty <= shortest) | (duty >= 1.0 - shortest)) * 100),
        "current_command_std_ma": float(np.std(settled[:, COLUMN["current_command_a"]]) * 1e3),
    }


def metrics(setup: SelfSensingSetup, values: dict, duration_s: float) -> dict:
    """The runs on ŝ at the settings (``SPREAD_SEEDS`` seeds from the set one: the first one's
    figures, the ratios' mean over all with its standard error), the spread's statistical error
    one run can hold, and the largest f_c a noise-free nonlinear run holds against the linear
    analysis's limit."""
    control_ = loop_control(values)
    reference = setup.gap_1_m
    at_reference = linear_loop(setup, control_, reference)
    runs = [spread_run(setup, control_, at_reference, int(values["seed"]) + k, duration_s) for k in range(SPREAD_SEEDS)]
    over_seeds = {}
    for name in ("gap_std_to_predicted", "gap_std_to_eq32_prediction", "duty_std_to_predicted",
                 "duty_at_limit_percent"):
        each = np.array([run[name] for run in runs])
        over_seeds[f"{name}_seeds"] = each.tolist()
        over_seeds[f"{name}_mean"] = float(np.mean(each))
        over_seeds[f"{name}_standard_error"] = float(np.std(each, ddof=1) / np.sqrt(len(each)))
    settled_periods = round((duration_s - SETTLE_S) / setup.period_s)
    duty_spread = predicted_duty_spread(at_reference, runs[0]["estimate_error_std_um"] * 1e-6)
    shortest = shortest_duty(setup, control_)
    low, high = stable_bandwidths_rad_s(setup, control_, reference)
    quiet = replace(setup, sigma_current_a=0.0, sigma_voltage_v=0.0, trajectory=TRAJECTORIES[1])
    held, lost = 0.8 * high, 1.2 * high
    for _ in range(LIMIT_STEPS):
        middle = 0.5 * (held + lost)
        if holds(quiet, control_._replace(bandwidth_rad_s=middle), LIMIT_RUN_S, 0):
            held = middle
        else:
            lost = middle
    above = LevitatedLoop(quiet, control_._replace(bandwidth_rad_s=1.1 * high))
    above.run(round(LIMIT_RUN_S / setup.period_s))
    return {
        **runs[0],
        **over_seeds,
        "held_s_least": min(run["held_s"] for run in runs),
        "spread_relative_error_one_run": spread_relative_error(at_reference, settled_periods),
        "predicted_duty_std": duty_spread,
        "duty_limit_margin_sigma": duty_limit_margin(at_reference, shortest, duty_spread),
        "lowest_stable_bandwidth_hz": low / (2 * np.pi),
        "largest_stable_bandwidth_hz": high / (2 * np.pi),
        "nonlinear_limit_hz": 0.5 * (held + lost) / (2 * np.pi),
        "nonlinear_limit_to_predicted": 0.5 * (held + lost) / high,
        "stops_at_1_1_limit": float(bool(above.stop_message)),
        "stop_message_above_limit": above.stop_message,
    }
