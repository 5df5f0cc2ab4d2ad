"""self_sensing's statistics: what the claims and readouts read from per-period rows of
``loops.self_sensing_loop`` (stationary runs at one gap, and the run over the moves)."""

from __future__ import annotations

import numpy as np

from lab_modules.loops.self_sensing_loop import COLUMN


def statistics(rows: np.ndarray, reference: np.ndarray | None = None) -> dict:
    """What the claims read from one stationary run (``reference``: the same gap measured ideally)."""
    c = COLUMN
    truth = rows[:, c["inductance_true_h"]]
    estimates = {"phase_1": rows[:, c["inductance_1_h"]], "phase_2": rows[:, c["inductance_2_h"]],
                 "mean": rows[:, c["inductance_mean_h"]]}
    error = estimates["mean"] - truth
    sigma = rows[:, c["sigma_inductance_mean_h"]]
    gap_error = rows[:, c["gap_estimated_m"]] - rows[:, c["gap_true_m"]]
    result = {
        "inductance_true_mh": float(np.mean(truth) * 1e3),
        "duty": float(np.mean(rows[:, c["duty"]])),
        "half_period_error_percent": {k: float(np.mean(v / truth - 1.0) * 100) for k, v in estimates.items()},
        "max_relative_error": {k: float(np.max(np.abs(v / truth - 1.0))) for k, v in estimates.items()},
        "inductance_ratio": float(np.mean(estimates["mean"] / truth)),
        "position_bias_um": float(np.mean(gap_error) * 1e6),
        "position_error_max_um": float(np.max(np.abs(gap_error)) * 1e6),
        "sigma_current_ma": float(np.mean(rows[:, [c["sigma_current_1_a"], c["sigma_current_2_a"]]]) * 1e3),
        "predicted_sigma_half_period_uh": {"phase_1": float(np.mean(rows[:, c["sigma_inductance_1_h"]]) * 1e6),
                                           "phase_2": float(np.mean(rows[:, c["sigma_inductance_2_h"]]) * 1e6)},
        "predicted_sigma_inductance_uh": float(np.mean(sigma) * 1e6),
        "predicted_sigma_position_um": float(np.mean(rows[:, c["sigma_gap_m"]]) * 1e6),
        "empirical_sigma_inductance_uh": float(np.std(error) * 1e6),
        "monte_carlo_to_predicted_ratio": float(np.std(error) / np.mean(sigma)),
        "within_3sigma_percent": float(np.mean(np.abs(error) <= 3.0 * sigma) * 100),
        "weights": [float(np.mean(rows[:, c["weight_1"]])), float(np.mean(rows[:, c["weight_2"]]))],
        "delta_current_ma": [float(np.mean(rows[:, c["delta_current_1_a"]]) * 1e3),
                             float(np.mean(rows[:, c["delta_current_2_a"]]) * 1e3)],
        "periods": len(rows),
    }
    if reference is not None:
        ideal = {"phase_1": reference[:, c["inductance_1_h"]], "phase_2": reference[:, c["inductance_2_h"]],
                 "mean": reference[:, c["inductance_mean_h"]]}
        result["shift_vs_ideal_uh"] = {k: float((np.mean(estimates[k]) - np.mean(ideal[k])) * 1e6) for k in ideal}
    return result


IDEAL = {"current_gain": 1.0, "voltage_gain": 1.0, "current_offset_a": 0.0, "voltage_offset_v": 0.0,
         "sigma_current_a": 0.0, "sigma_voltage_v": 0.0, "resistance_ratio": 1.0, "printed_eq7": False}



def trajectory_statistics(rows: np.ndarray) -> dict:
    """The largest errors of the run over the prescribed moves (per-period rows, COLUMNS first)."""
    c = COLUMN
    truth = rows[:, c["inductance_true_h"]]
    moving = np.abs(np.gradient(rows[:, c["gap_true_m"]])) > 0
    return {
        "mean_max_relative_error": float(np.max(np.abs(rows[:, c["inductance_mean_h"]] / truth - 1.0))),
        "phase_1_max_relative_error": float(np.max(np.abs(rows[:, c["inductance_1_h"]]
                                                          / rows[:, c["inductance_1_true_h"]] - 1.0))),
        "phase_2_max_relative_error": float(np.max(np.abs(rows[:, c["inductance_2_h"]]
                                                          / rows[:, c["inductance_2_true_h"]] - 1.0))),
        "position_error_max_um": float(np.max(np.abs(rows[:, c["gap_estimated_m"]]
                                                     - rows[:, c["gap_true_m"]])) * 1e6),
        "moving_periods": int(np.sum(moving)),
        "periods": len(rows),
    }


def eq25_shift_h(ideal: np.ndarray, offset_v: float, offset_a: float, resistance_ohm: float,
                 samples_per_period: int, trim_samples: int, sample_time_s: float) -> np.ndarray:
    """Eq. 25 per period: the shift L̄_m − L̄ [H] an offset Δv [V], Δi [A] (eq. 23) causes,

        L̄_m − L̄ = −(īᴵᴵ − īᴵ)(Δv − R Δi) Δtᴵ Δtᴵᴵ / (Δiᴵ īᴵᴵ Δtᴵᴵ − Δiᴵᴵ īᴵ Δtᴵ),

    with Δi, ī of the error-free run ``ideal`` (rows) and the windows' lengths Δt from its duties."""
    c = COLUMN
    on = np.rint(ideal[:, c["duty"]] * samples_per_period)
    window_1 = (on - 2 * trim_samples) * sample_time_s                          # Δtᴵ [s]
    window_2 = (samples_per_period - on - 2 * trim_samples) * sample_time_s     # Δtᴵᴵ [s]
    mean_1, mean_2 = ideal[:, c["mean_current_1_a"]], ideal[:, c["mean_current_2_a"]]
    rise_1, rise_2 = ideal[:, c["delta_current_1_a"]], ideal[:, c["delta_current_2_a"]]
    return -((mean_2 - mean_1) * (offset_v - resistance_ohm * offset_a) * window_1 * window_2
             / (rise_1 * mean_2 * window_2 - rise_2 * mean_1 * window_1))


def moving_offset_shift(rows: np.ndarray, ideal: np.ndarray, predicted_h: np.ndarray) -> dict:
    """The shift of L̄ an offset causes during the moves (Fig. 3): the largest |L̄ − L̄_ideal| over
    the moving periods, and the measured shift against eq. 25 where it is largest."""
    c = COLUMN
    moving = np.abs(np.gradient(ideal[:, c["gap_true_m"]])) > 0
    shift = (rows[:, c["inductance_mean_h"]] - ideal[:, c["inductance_mean_h"]])[moving]
    largest = int(np.argmax(np.abs(shift)))
    return {"shift_max_uh": float(np.abs(shift[largest]) * 1e6),
            "shift_max_relative": float(np.abs(shift[largest]) / ideal[moving, c["inductance_mean_h"]][largest]),
            "shift_at_rest_max_uh": float(np.max(np.abs((rows[:, c["inductance_mean_h"]]
                                                          - ideal[:, c["inductance_mean_h"]])[~moving])) * 1e6),
            "shift_to_eq25": float(shift[largest] / predicted_h[moving][largest])}
