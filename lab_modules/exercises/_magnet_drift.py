"""adaptive_filter's magnet-drift run (paper 002, Figs. 1 and 8 online; ``loops.magnet_drift_loop``):
its controls, its programme, the force-estimate bias after the k_Magnet change, the filters'
consistency (NEES, NIS with 95 % χ² bounds, ``estimators.filter_consistency``) and its plots.

Programme (period 0.8 s): centre; point 1 (move at 50 ms, load from 100 ms) held to 450 ms with
the drift at 200 ms; centre; point 2 (move at 500 ms, load from 550 ms) to 800 ms.  Windows: the
last 100 ms at point 1 (350-450 ms) and at point 2 (700-800 ms).

Bias: the mean force-estimate error F̂_St - F_St over ``BIAS_SEEDS`` runs (noise seeds seed,
seed + 1, ...), averaged over the last 10 ms: the expected error, not one run's noise (σ ≈ 0.6 N per sample).
The time to 10 %: from the adaptive bias's peak after the change, the first time it is under 10 % of
the offline filter's bias at point 1 (its window mean).  The time the lab states is the ADALINE's, from
its step size: the weight error decays as (1 - η φ²)^k (eq. 24), so

    t_10% = T ln 10 / (η φ₁²) + 10 ms,   φ₁ = F₁ / k_Magnet,after   [A²/mm²]         (point 1's force F₁)

the 10 ms for the trailing mean the bias is read through; the filter's own force lag (its error
poles) adds a few ms more, so the measured time may exceed the stated one by a little.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from lab_modules.estimators.adaline import miso_run, siso_run
from lab_modules.estimators.filter_consistency import (
    ConsistencyTest,
    integrated_autocorrelation_time,
    normalised_test,
)
from lab_modules.exercises import Plot
from lab_modules.loops.axial_bearing_loop import LoopSetup, Segment
from lab_modules.loops.magnet_drift_loop import (
    COLUMN,
    FILTERS,
    NEES_STATES,
    TARGETS,
    DriftSetup,
    DriftSimulation,
)
from lab_modules.parameters import Parameter, in_si
from lab_modules.plants.axial_bearing import AXIAL, force_shape

T = DriftSimulation.sample_time_s
PERIOD_S = 0.8
POINT1_END_S = 0.45
WINDOWS = {"point 1": (0.35, 0.45), "point 2": (0.7, 0.8)}
BIAS_SEEDS = 8
SMOOTHING_S = 0.01
MISO_RATE = 0.1                # 1/A²: the MISO ADALINE's step (stiffness_map's default; i in A, x in mm)
MISO_SEED_OFFSET = 7919        # the force sensor's noise is drawn apart from the loop's
PEAK_SEARCH_S = 0.05           # the adaptive bias peaks within this time after the change
LABELS = {"fixed": "fixed k_i, k_s", "offline": "scheduled offline (FBFNN, nominal law)",
          "adaptive": "adaptive (FBFNN × k̂/k₀, ADALINE)", "exact": "exact (EKF, true k_Magnet)"}
COLORS = {"fixed": "#ff7f0e", "offline": "#d62728", "adaptive": "#17becf", "exact": "#2ca02c"}
K_NOMINAL_MM = AXIAL.k_magnet_n_m2_per_a2 * 1e6            # 6.7 N·mm²/A²

P = Parameter
CONTROLS = (
    P("k_magnet_change_pct", "k_Magnet change", "%", -10.0, -30.0, 30.0,
      "How much the magnet's k_Magnet changes during the drift run (heating, ageing).", step=1.0,
      group="Magnet drift"),
    P("k_magnet_change_ms", "k_Magnet change at", "ms", 200.0, 110.0, 400.0,
      "When the change begins within the 800 ms programme (the rotor is at point 1 from 100 to 450 ms).",
      step=5.0, group="Magnet drift"),
    P("k_magnet_ramp_ms", "k_Magnet ramp time", "ms", 0.0, 0.0, 200.0,
      "0: a step; else the change spreads linearly over this time.", step=5.0, group="Magnet drift"),
    P("adaline_rate", "ADALINE step size η", "mm⁴/A⁴", 0.003, 1e-4, 0.05,
      "Step size of eq. 24 on k̂_Magnet; above about 0.006 the identification rings with the filter's force lag.",
      log=True, group="Magnet drift"),
    P("adaline_target", "ADALINE target", "", TARGETS[0], choices=TARGETS,
      description="force balance: the adaptive filter's magnet-force estimate less the applied load; "
                  "force sensor: the true magnet force plus white noise σ_F.", group="Magnet drift"),
    P("force_sensor_noise_n", "Force sensor noise σ_F", "N", 0.5, 0.0, 5.0,
      "White noise of the force sensor (only with the force-sensor target).", step=0.05, group="Magnet drift"),
    P("covariance_propagation", "P of the scheduled filters", "", "secant factors",
      choices=("secant factors", "Jacobian"),
      description="secant factors: P moves with the k_i, k_s the state uses; Jacobian: with the tangent "
                  "factors of eq. 1 at the estimate.", group="Magnet drift"),
)


def drift_setup(values: dict, loop: LoopSetup) -> DriftSetup:
    """The drift run on the exercise's loop settings: its own programme (module docstring)."""
    si = in_si(CONTROLS, values)
    weight = AXIAL.weight_n
    x1, x2 = values["point1_position_mm"] * 1e-3, values["point2_position_mm"] * 1e-3
    segments = (Segment(0.0, 0.0, 0.0), Segment(0.05, x1, 0.0), Segment(0.1, x1, weight - values["point1_force_n"]),
                Segment(POINT1_END_S, 0.0, 0.0), Segment(0.5, x2, 0.0),
                Segment(0.55, x2, weight - values["point2_force_n"]))
    loop = replace(loop, segments=segments, period_s=PERIOD_S, adaline_rate=values["adaline_rate"],
                   force_noise_n=values["force_sensor_noise_n"])
    return DriftSetup(loop, start_s=si["k_magnet_change_ms"], ramp_s=si["k_magnet_ramp_ms"],
                      change=values["k_magnet_change_pct"] / 100.0, target=values["adaline_target"],
                      jacobian=values["covariance_propagation"] == "Jacobian")


def run(setup: DriftSetup, seed: int) -> tuple[np.ndarray, str]:
    simulation = DriftSimulation(setup, seed=seed)
    return simulation.advance(round(PERIOD_S / T)), simulation.status_message()


def stated_time_ms(values: dict) -> float:
    """t_10% = T ln 10 / (η φ₁²) + 10 ms [ms] (module docstring)."""
    phi = values["point1_force_n"] / (K_NOMINAL_MM * (1.0 + values["k_magnet_change_pct"] / 100.0))   # A²/mm²
    return 1e3 * (T * np.log(10.0) / (values["adaline_rate"] * phi**2) + SMOOTHING_S)


def smoothed(signal: np.ndarray) -> np.ndarray:
    """The mean over the last ``SMOOTHING_S`` (trailing: no look ahead)."""
    n = max(1, round(SMOOTHING_S / T))
    return np.convolve(signal, np.ones(n) / n)[:signal.size]


def consistency(trace: np.ndarray, window: tuple[float, float]) -> dict[str, tuple[ConsistencyTest, ...]]:
    """(NEES over x, v, F_St; NIS) of each filter over ``window`` [s]; NEES bounds on the samples
    that are independent (``filter_consistency.integrated_autocorrelation_time``)."""
    t = trace[:, 0]
    inside = (t >= window[0] - 1e-9) & (t < window[1] - 1e-9)
    out = {}
    for f in FILTERS:
        nees, nis = trace[inside, COLUMN[f"{f}_nees"]], trace[inside, COLUMN[f"{f}_nis"]]
        if nees.size == 0:
            continue
        out[f] = (normalised_test("NEES", nees, NEES_STATES, int(nees.size / integrated_autocorrelation_time(nees))),
                  normalised_test("NIS", nis, 1, nis.size))
    return out


def identifier_errors(traces: list[np.ndarray], values: dict, start_s: float, seed: int) -> dict[str, float]:
    """SISO against MISO ADALINE on the same drift runs (issue: "the MISO variant where it helps").

    Both run offline over each run's coil current i, the adaptive filter's x̂ and a force sensor
    (the true magnet force plus white noise σ_F, drawn from ``seed`` + ``MISO_SEED_OFFSET``), so they
    differ only in their structure: SISO F̂ = k̂ φ(i, x̂) (eq. 1, one weight for the whole map, η of
    the exercise); MISO F̂ = w_i i + w_s x̂ (x in mm, the local slopes, η = ``MISO_RATE``), both from
    the nominal law.  Returns the RMS of the a-priori F̂ − F [N] over the seeds in each of
    ``identifier_windows`` (keys "siso_rms_n", "miso_rms_n") and their ratios ("miso_over_siso")."""
    gap, bias = AXIAL.nominal_gap_m, AXIAL.bias_current_a
    windows = identifier_windows(start_s)
    errors = {"siso": [], "miso": []}
    rng = np.random.default_rng(seed + MISO_SEED_OFFSET)
    for trace in traces:
        current = np.ascontiguousarray(trace[:, COLUMN["current_a"]])
        x_hat = trace[:, COLUMN["x_true_m"]] + trace[:, COLUMN["adaptive_x_error_m"]]
        force = trace[:, COLUMN["magnet_force_n"]]
        sensed = force + values["force_sensor_noise_n"] * rng.standard_normal(force.size)
        phi = force_shape(current, x_hat, gap, bias) * 1e-6                  # φ [A²/mm²]
        siso = np.empty(force.size)
        siso_run(K_NOMINAL_MM, phi, sensed, values["adaline_rate"], siso)   # a priori F̂ = k̂ φ
        weights = np.array([4 * K_NOMINAL_MM * bias / (gap * 1e3) ** 2,      # k_i = 4 k_M i0 / s0² [N/A]
                            4 * K_NOMINAL_MM * bias**2 / (gap * 1e3) ** 3])  # k_s = 4 k_M i0² / s0³ [N/mm]
        miso = np.empty((force.size, 3))
        miso_run(weights, current, np.ascontiguousarray(x_hat * 1e3), np.ascontiguousarray(sensed), MISO_RATE, miso)
        errors["siso"].append(siso - force)
        errors["miso"].append(miso[:, 0] - force)
    t = traces[0][:, 0]
    out = {"siso_rms_n": {}, "miso_rms_n": {}, "miso_over_siso": {}}
    for name, (a, b) in windows.items():
        inside = (t >= a) & (t < b)
        for kind, per_run in errors.items():
            out[f"{kind}_rms_n"][name] = float(np.sqrt(np.mean([np.mean(e[inside] ** 2) for e in per_run])))
        out["miso_over_siso"][name] = out["miso_rms_n"][name] / out["siso_rms_n"][name]
    return out


def identifier_windows(start_s: float) -> dict[str, tuple[float, float]]:
    """The windows of ``identifier_errors`` [s]: 100 ms after the change, point 1, the move, point 2."""
    return {"after the change": (start_s, start_s + 0.1), "point 1": WINDOWS["point 1"],
            "the move": (POINT1_END_S, WINDOWS["point 2"][0]), "point 2": WINDOWS["point 2"]}


def drift_results(values: dict, loop: LoopSetup) -> dict:
    """The seeds' runs: mean bias curves, the time to 10 %, the windows' biases and consistency."""
    setup = drift_setup(values, loop)
    seed = int(values["seed"])
    runs = [run(setup, seed + j) for j in range(BIAS_SEEDS)]
    trace, status = runs[0]
    n = min(r[0].shape[0] for r in runs)
    t = trace[:n, 0]
    bias = {f: smoothed(np.mean([r[0][:n, COLUMN[f"{f}_force_error_n"]] for r in runs], axis=0)) for f in FILTERS}
    windows = {}
    for name, (a, b) in WINDOWS.items():
        w = (t >= a) & (t < b)
        windows[name] = {f: float(np.mean(bias[f][w])) if w.any() else float("nan") for f in FILTERS}
    start = setup.start_s + setup.ramp_s
    after = np.flatnonzero((t >= start) & (t < POINT1_END_S))
    adaptive = np.abs(bias["adaptive"][after])
    peak = int(np.argmax(adaptive[:round(PEAK_SEARCH_S / T)])) if after.size else 0
    # from its peak after the change, the first time the adaptive bias is under 10 % of the offline one
    below = np.flatnonzero(adaptive[peak:] < 0.1 * abs(windows["point 1"]["offline"]))
    time_ms = 1e3 * (t[after[peak + below[0]]] - start) if below.size else float("nan")
    return {"t": t, "bias": bias, "k_estimate": np.mean([r[0][:n, COLUMN["k_magnet_estimate"]] for r in runs], axis=0),
            "k_true": trace[:n, COLUMN["k_magnet_true"]], "time_to_10pct_ms": float(time_ms),
            "stated_ms": stated_time_ms(values), "windows": windows, "status": status or "ok",
            "consistency": {name: consistency(trace, w) for name, w in WINDOWS.items()}, "trace": trace,
            "identifiers": identifier_errors([r[0][:n] for r in runs], values, start, seed)}


def plots(results: dict) -> list[Plot]:
    pick = np.arange(0, results["t"].size, 5)
    t = 1e3 * results["t"][pick]
    bias = Plot(f"Magnet drift: mean force-estimate error F̂_St - F_St over {BIAS_SEEDS} seeds", "time [ms]",
                "F̂_St - F_St [N]", t, tuple((LABELS[f], results["bias"][f][pick], COLORS[f]) for f in FILTERS))
    k = Plot("Magnet drift: k_Magnet and the ADALINE's k̂ (mean over the seeds)", "time [ms]", "k_Magnet [N·mm²/A²]",
             t, (("true", results["k_true"][pick], "#1f77b4"), ("ADALINE k̂", results["k_estimate"][pick], "#17becf")))
    trace = results["trace"]
    nis = Plot("Magnet drift: NIS, mean over 10 ms (consistent: about 1)", "time [ms]", "NIS [-]",
               1e3 * trace[pick, 0],
               tuple((LABELS[f], np.convolve(trace[:, COLUMN[f"{f}_nis"]], np.ones(100) / 100, "same")[pick],
                      COLORS[f]) for f in FILTERS))
    return [bias, k, nis]


def readouts(results: dict) -> list[tuple[str, float, str]]:
    out = [("Drift: adaptive bias under 10 % of the offline one after", results["time_to_10pct_ms"], "ms"),
           ("Drift: stated time T ln10 / (η φ₁²) + 10 ms", results["stated_ms"], "ms")]
    for name, biases in results["windows"].items():
        out += [(f"Drift: F̂_St bias, {LABELS[f]}, {name}", biases[f], "N") for f in FILTERS]
    for name, tests in results["consistency"].items():
        for f, found in tests.items():
            out += [(f"Drift: {test.name}, {f}, {name} (95 %: {test.lower:.2f}–{test.upper:.2f}, {test.verdict})",
                     test.mean, "") for test in found]
    ratios = results["identifiers"]["miso_over_siso"]
    out += [(f"Drift: force-error RMS, MISO / SISO ADALINE, {name}", ratio, "×") for name, ratio in ratios.items()]
    return out


def live_readouts(trace: dict[str, np.ndarray], window_s: float) -> list[tuple[str, float, str]]:
    """NEES and NIS of each filter over the newest ``window_s`` of the scope, with their bounds."""
    n = round(window_s / T)
    out = []
    for f in FILTERS:
        nees, nis = trace[f"drift_{f}_nees"][-n:], trace[f"drift_{f}_nis"][-n:]
        for test in (normalised_test("NEES", nees, NEES_STATES, int(nees.size / integrated_autocorrelation_time(nees))),
                     normalised_test("NIS", nis, 1, nis.size)):
            out.append((f"Drift: {test.name}, {f} (95 %: {test.lower:.2f}–{test.upper:.2f})", test.mean, ""))
    return out
