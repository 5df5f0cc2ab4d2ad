"""self_sensing's views: the ripple zoom of two PWM periods with the fitted lines over the
least-squares windows (eq. 9-10), the histogram of the normalised inductance error against
N(0, 1) and the Monte-Carlo check of eq. 31 (Fig. 6), the scope window's readouts."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from lab_modules.estimators.ripple_inductance import fit
from lab_modules.exercises import Analysis, Plot
from lab_modules.loops.self_sensing_loop import COLUMN, SelfSensingSetup

from ._self_sensing_statistics import statistics

RIPPLE_PERIODS = 2           # PWM periods in the ripple zoom


def histogram(normalised: np.ndarray, where: str = "gap 1") -> Plot:
    """(L̄ − L)/σ̂ against the standard normal density."""
    normalised = normalised[np.isfinite(normalised)]
    edges = np.linspace(-4.0, 4.0, 33)
    counts, _ = np.histogram(normalised, bins=edges)
    centres = 0.5 * (edges[1:] + edges[:-1])
    density = counts / (max(len(normalised), 1) * (edges[1] - edges[0]))
    return Plot(f"Monte-Carlo at {where}: (L̄ − L)/σ̂(L̄) per PWM period against N(0, 1)",
                "normalised error (L̄ − L)/σ̂ [1]", "density [1]", centres,
                (("histogram", density, "#1f77b4"),
                 ("N(0, 1)", np.exp(-0.5 * centres**2) / math.sqrt(2 * math.pi), "#d62728")))


def ripple_plots(s: SelfSensingSetup, raw: np.ndarray, duties: np.ndarray, title: str,
                 points: int | None = None) -> list[Plot]:
    """The ripple zoom of two PWM periods from their raw samples (rows: time, true i, measured
    i, measured v, applied v; ``duties`` per period): true and measured current, the LS
    windows (shaded), the lines fitted over them (eq. 9-10) and the voltage.  ``points``:
    draw every k-th sample, at most this many (the fits use them all).  Before two periods
    have run, the plots are empty (zeros) with the same series."""
    n = s.samples_per_period
    total = RIPPLE_PERIODS * n
    step = 1 if points is None else -(-total // points)
    shown = np.arange(0, total, step)
    t_us = shown * s.sample_time_s * 1e6
    ready = len(raw) == total and len(duties) == RIPPLE_PERIODS
    raw = raw if ready else np.zeros((total, 5))
    r_hat = s.resistance_ratio * s.rig.coil_resistance_ohm * (-1.0 if s.printed_eq7 else 1.0)
    dof = "M + d" if s.printed_dof else "M-d"
    fits, windows = [], []
    for p in range(RIPPLE_PERIODS):
        n_on = round(duties[p] * n) if ready else n // 2
        current, voltage = raw[p * n:(p + 1) * n, 2], raw[p * n:(p + 1) * n, 3]
        # phase II ends one sample early: the sample after the period is not in ``raw``
        for phase, (start, stop) in enumerate(((s.trim_samples, n_on - s.trim_samples),
                                               (n_on + s.trim_samples, n - s.trim_samples - 1))):
            line = np.full(len(shown), np.nan)
            windows.append(((p * n + start) * s.sample_time_s * 1e6,
                            (p * n + stop) * s.sample_time_s * 1e6))
            if ready:
                result = fit(current, voltage, start, stop, r_hat, s.sample_time_s, dof)
                flux = np.concatenate([[0.0], np.cumsum(voltage[start:stop] - r_hat * current[start:stop])])
                inside = np.flatnonzero((shown >= p * n + start) & (shown <= p * n + stop))
                # the line at ≤ 17 points of the window (NaN elsewhere costs next to nothing on the wire)
                inside = inside[np.unique(np.linspace(0, len(inside) - 1, min(len(inside), 17)).round().astype(int))]
                line[inside] = (result["initial_current_a"]
                                + s.sample_time_s / result["inductance_h"] * flux[shown[inside] - p * n - start])
            fits.append((f"fit {'I' * (phase + 1)}, period {p + 1}", line, "#ff7f0e" if phase == 0 else "#2ca02c"))
    raw = raw[shown]
    windows = tuple(windows)
    return [
        Plot(title, "time [µs]", "current [A]", t_us,
             (("measured i_m", raw[:, 2], "#a0a0a0"), ("true i", raw[:, 1], "#000000"), *fits), shade=windows),
        Plot("Bridge voltage of the same two periods", "time [µs]", "voltage [V]", t_us,
             (("applied v", raw[:, 4], "#000000"), ("measured v_m", raw[:, 3], "#9467bd")), shade=windows),
    ]



def monte_carlo_views(run: Callable[[int], np.ndarray], seeds: int, periods: int, gap_mm: float, noisy: bool):
    """The Monte-Carlo check of eq. 31 at one gap (§5, Fig. 6) as it progresses: ``run(k)`` gives the
    per-period rows of seed k; yields an ``Analysis`` (ratio of the empirical std of L̄ − L to the mean
    σ̂(L̄), share inside ±3σ̂, histogram) after every seed."""
    c = COLUMN
    notes = [] if noisy else [
        ("No noise is set: σ̂ only measures the ramp's curvature and the ratio means little. "
         "Set σ(i) = 1 mA, σ(v) = 15 mV (§5).")]
    runs = []
    yield Analysis([("Periods simulated", 0, f"of {seeds * periods}")], {},
                   [f"Monte-Carlo at {gap_mm:g} mm: seed 1 of {seeds} …", *notes])
    for k in range(seeds):
        runs.append(run(k))
        rows = np.concatenate(runs)
        st = statistics(rows)
        normalised = ((rows[:, c["inductance_mean_h"]] - rows[:, c["inductance_true_h"]])
                      / rows[:, c["sigma_inductance_mean_h"]])
        done = k + 1 == seeds
        progress = (f"Monte-Carlo at {gap_mm:g} mm: {k + 1} of {seeds} seeds done"
                    + ("." if done else f", seed {k + 2} running …"))
        yield Analysis([
            ("MC std of L̄ − L / predicted σ̂(L̄)", st["monte_carlo_to_predicted_ratio"], ""),
            ("Share of L̄ − L inside ±3σ̂(L̄)", st["within_3sigma_percent"], "%"),
            ("Periods", st["periods"], f"({k + 1} seeds × {periods})"),
            ("Empirical std of L̄ − L", st["empirical_sigma_inductance_uh"], "µH"),
            ("Mean predicted σ̂(L̄) (eq. 31)", st["predicted_sigma_inductance_uh"], "µH"),
        ], {}, [progress, *notes], [histogram(normalised, f"{gap_mm:g} mm")])


def live_readouts(trace: dict[str, np.ndarray], last_periods: int) -> list[tuple[str, float, str]]:
    """The scope window's readouts (the newest period, or the last ``last_periods``)."""
    last = slice(-last_periods, None)
    error = trace["inductance_error_h"][last]
    sigma = trace["sigma_inductance_mean_h"][last]
    return [
        ("True L (newest period)", float(trace["inductance_true_h"][-1] * 1e3), "mH"),
        ("L̄ (newest period)", float(trace["inductance_mean_h"][-1] * 1e3), "mH"),
        ("L̄/L, the estimate μ̂ (mean; eq. 22)", float(np.mean(trace["inductance_ratio"][last])), ""),
        ("L/L̄, the estimate η̂ (mean; eq. 22)", float(np.mean(trace["voltage_gain_estimate"][last])), ""),
        ("Position bias ŝ − s (mean)", float(np.mean(trace["gap_error_m"][last]) * 1e6), "µm"),
        ("Duty χ", float(trace["duty"][-1]), ""),
        ("Δiᴵ", float(trace["delta_current_1_a"][-1] * 1e3), "mA"),
        ("Δiᴵᴵ", float(trace["delta_current_2_a"][-1] * 1e3), "mA"),
        ("Weight wᴵ", float(trace["weight_1"][-1]), ""),
        ("Weight wᴵᴵ", float(trace["weight_2"][-1]), ""),
        ("σ̂(i) (mean of both phases)", float(np.mean(trace["sigma_current_1_a"][last]
                                                       + trace["sigma_current_2_a"][last]) * 500), "mA"),
        ("σ̂(L̄) (mean)", float(np.mean(sigma) * 1e6), "µH"),
        ("σ̂(ŝ) (mean)", float(np.mean(trace["sigma_gap_shown_m"][last]) * 1e6), "µm"),
        (f"Empirical std of L̄ − L (last {last_periods} periods)", float(np.std(error) * 1e6), "µH"),
        ("L̄ − L inside ±3σ̂", float(np.mean(np.abs(error) <= 3 * sigma) * 100), "%"),
    ]
