"""thrust_liftoff's filter comparison: the extended Kalman filter (eq. 2 re-linearised at its
estimate every sample, ``estimators.thrust_ekf``) against the paper's linear filter (eq. 9-11),
each with and without the touchdown stop in its model.

Compared where the difference lives: on the nonlinear plant (eq. 2), with the estimate fed back.
On the linear plant (eq. 5, the paper's simulation) the linear filter's model is the true one.
Per filter: the largest |x̂ − x| in the noise-free lift-off (model error alone), the RMS of
x̂ − x in noisy lift-offs (the first ``LIFTOFF_WINDOW_S``) and at steady state, and the NEES and
NIS of those two windows pooled over the seeds with their 95 % bounds (``filter_consistency``).
The bounds mean something only when the plant's noise is the filter's (σ_f² = Q, R = σ_v²).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from lab_modules.claims import Claim
from lab_modules.estimators.filter_consistency import (
    integrated_autocorrelation_time,
    nees_samples,
    nis_samples,
    normalised_test,
)
from lab_modules.loops.thrust_liftoff_loop import ThrustSetup, ThrustSimulation

#: The filters compared: ThrustSetup fields of each.
FILTERS = {"linear": {"filter_extended": False, "filter_knows_stop": False},
           "linear_stop": {"filter_extended": False, "filter_knows_stop": True},
           "extended": {"filter_extended": True, "filter_knows_stop": False},
           "extended_stop": {"filter_extended": True, "filter_knows_stop": True}}
LABELS = {"linear": "linear (eq. 9-11)", "linear_stop": "linear + stop", "extended": "EKF (eq. 2)",
          "extended_stop": "EKF + stop"}
COLOURS = {"linear": "#1f77b4", "linear_stop": "#17becf", "extended": "#ff7f0e", "extended_stop": "#d62728"}
NOISY = ("linear", "extended_stop")
LIFTOFF_WINDOW_S = 0.3           # the lift-off has peaked (50 ms) and settled within 2 % (0.21 s) by then
CONSISTENCY_WINDOW_S = 0.4       # the steady-state NEES/NIS window: what the debugger's tape keeps (4000 samples)


def compared_setup(setup: ThrustSetup, name: str, **changes) -> ThrustSetup:
    """``setup`` on the nonlinear plant with the estimate fed back and filter ``name`` (Taylor
    matrices for the linear one)."""
    return replace(setup, nonlinear=True, use_estimate=True, filter_exact_model=False, **FILTERS[name], **changes)


def noise_free_errors(setup: ThrustSetup, duration_s: float = LIFTOFF_WINDOW_S) -> dict[str, dict]:
    """Each filter's noise-free lift-off: time [s], x̂ − x [m] and the status ("" when it ran through)."""
    out = {}
    for name in FILTERS:
        sim = ThrustSimulation(compared_setup(setup, name, noise_on=False))
        trace = sim.run(duration_s)
        out[name] = {"time_s": trace["time_s"], "error_m": trace["estimation_error_m"], "status": sim.status_message()}
    return out


def pooled_test(name: str, histories: list, samples_of) -> dict:
    """A NEES or NIS test over several windows (one per seed): samples and independent samples add."""
    samples, independent, dof = [], 0, 1
    for history in histories:
        if name == "NEES":
            values, dof = samples_of(history)
            independent += int(len(values) / integrated_autocorrelation_time(values))
        else:
            values = samples_of(history)
            independent += len(values)
        samples.append(values)
    test = normalised_test(name, np.concatenate(samples), dof, independent)
    return {"mean": test.mean, "lower": test.lower, "upper": test.upper,
            "band_position": (test.mean - test.lower) / (test.upper - test.lower)}   # 0 lower bound, 1 upper


def comparison(setup: ThrustSetup, duration_s: float, seeds: range, steady_from_s: float) -> dict[str, dict]:
    """Per filter: the noise-free lift-off's largest |x̂ − x| [µm] (all of ``FILTERS``); for the
    linear filter and the EKF with the stop (``NOISY``) also the noisy figures over ``seeds``: RMS
    errors [µm] (mean of the seeds) in the lift-off and from ``steady_from_s`` on, their ratios to
    the linear filter's, and NEES and NIS pooled over the seeds in the lift-off window and in the
    last ``CONSISTENCY_WINDOW_S`` of the run (the filter debugger's tape, replayed)."""
    noise_free = noise_free_errors(setup)
    out = {name: {"liftoff_peak_error_um": float(np.max(np.abs(run["error_m"]))) * 1e6}
           for name, run in noise_free.items()}
    steady_s = max(duration_s - LIFTOFF_WINDOW_S, 0.0)
    for name in NOISY:
        liftoff_rms, steady_rms, windows = [], [], {"liftoff": [], "steady": []}
        for seed in seeds:
            sim = ThrustSimulation(compared_setup(setup, name), seed=seed)
            first = sim.run(LIFTOFF_WINDOW_S)
            windows["liftoff"].append(sim.filter_tape().history())
            # the tape keeps whole runs: the last window as a run of its own keeps the replay short
            middle = sim.run(max(steady_s - CONSISTENCY_WINDOW_S, 0.0))
            last = sim.run(min(CONSISTENCY_WINDOW_S, steady_s))
            liftoff_rms.append(np.sqrt(np.mean(first["estimation_error_m"] ** 2)))
            time_s = np.concatenate([middle["time_s"], last["time_s"]])
            error = np.concatenate([middle["estimation_error_m"], last["estimation_error_m"]])[time_s >= steady_from_s]
            steady_rms.append(np.sqrt(np.mean(error**2)) if error.size else np.nan)
            if last["time_s"].size and last["time_s"][0] >= steady_from_s:
                windows["steady"].append(sim.filter_tape().history())
        figures = out[name]
        figures["liftoff_rms_error_um"] = float(np.mean(liftoff_rms)) * 1e6
        figures["steady_rms_error_um"] = float(np.mean(steady_rms)) * 1e6
        for window, histories in windows.items():
            if histories:
                figures[f"{window}_nees"] = pooled_test("NEES", histories, nees_samples)
                figures[f"{window}_nis"] = pooled_test("NIS", histories, nis_samples)
    base = out["linear"]
    for name in NOISY:
        out[name]["liftoff_rms_ratio_to_linear"] = out[name]["liftoff_rms_error_um"] / base["liftoff_rms_error_um"]
        out[name]["steady_rms_ratio_to_linear"] = out[name]["steady_rms_error_um"] / base["steady_rms_error_um"]
    return out


#: Settings of the comparison's claims: the nonlinear plant, and the plant's force noise equal to
#: the filter's Q (σ_f² = 2.64e6 N²), so that NEES and NIS have a consistent filter to find.
MATCHED_NONLINEAR = {"force_law": "nonlinear", "force_noise_n": 1625.0}
#: thrust_liftoff's claims on the comparison (its ``metrics`` key "filters").
FILTER_CLAIMS = (
    Claim("paper 003 §1.2 (lab evidence)", "EKF vs linear filter: noise-free lift-off, largest |x̂ − x|, "
          "linear filter", "not printed", "filters.linear.liftoff_peak_error_um", (6.5, 8.5), "µm",
          "Nonlinear plant, estimate fed back: eq. 4's fixed slopes miss eq. 2 away from the centre.",
          settings=MATCHED_NONLINEAR),
    Claim("paper 003 §1.2 (lab evidence)", "that error, EKF with the touchdown stop", "not printed",
          "filters.extended_stop.liftoff_peak_error_um", (None, 0.05), "µm",
          "Re-linearised at the estimate, and held at the stop as the collar is: nothing left to miss.",
          settings=MATCHED_NONLINEAR),
    Claim("paper 003 §1.2 (lab evidence)", "that error, EKF without the stop", "not printed",
          "filters.extended.liftoff_peak_error_um", (9.0, 12.5), "µm",
          "Worse than the linear filter: on the stop eq. 2's lower magnet pulls 86 kN at the smallest gap, "
          "and a filter that does not know the stop lets its estimate fall into it.",
          settings=MATCHED_NONLINEAR),
    Claim("paper 003 §1.2 (lab evidence)", "EKF with the stop / linear filter: RMS of x̂ − x in the noisy "
          "lift-off (first 0.3 s)", "not printed", "filters.extended_stop.liftoff_rms_ratio_to_linear",
          (None, 0.97), "×", "Mean of 3 seeds; the sensor noise's share of the error is the same for both.",
          settings=MATCHED_NONLINEAR),
    Claim("paper 003 §1.2 (lab evidence)", "EKF with the stop / linear filter: RMS of x̂ − x at steady state",
          "not printed", "filters.extended_stop.steady_rms_ratio_to_linear", (0.99, 1.01), "×",
          "At the centre the EKF's Jacobian is eq. 4's: the two filters are the same filter.",
          settings=MATCHED_NONLINEAR),
    Claim("lab (filter consistency)", "lift-off NEES of the EKF with the stop, place in its 95 % band",
          "not printed", "filters.extended_stop.liftoff_nees.band_position", (0.0, 1.0), "",
          "0 = lower, 1 = upper χ² bound, 3 seeds pooled; σ_f² = Q and R = σ_v², so a consistent "
          "filter lies inside.", settings=MATCHED_NONLINEAR),
    Claim("lab (filter consistency)", "lift-off NEES of the linear filter, place in its 95 % band",
          "not printed", "filters.linear.liftoff_nees.band_position", (1.0, None), "",
          "Above the band: during the lift-off the linear filter's error exceeds its P (overconfident).",
          settings=MATCHED_NONLINEAR),
    Claim("lab (filter consistency)", "steady-state NEES of the EKF with the stop, place in its 95 % band",
          "not printed", "filters.extended_stop.steady_nees.band_position", (0.0, 1.0), "",
          "Last 0.4 s of the run, 3 seeds pooled.", settings=MATCHED_NONLINEAR),
    Claim("lab (filter consistency)", "steady-state NIS of the EKF with the stop, place in its 95 % band",
          "not printed", "filters.extended_stop.steady_nis.band_position", (0.0, 1.0), "",
          "Last 0.4 s of the run, 3 seeds pooled.", settings=MATCHED_NONLINEAR),
)
