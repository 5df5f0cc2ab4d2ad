"""The step tests of ``lqg_vs_pid`` (paper 000, §IV, Figs. 8-9): both loops after the reference
step and after the disturbance step set on the controls, as figures (remembered per setting they
read), readouts and plots.  The runs
and their figures come from ``loops.radial_axis_step_tests``."""

from __future__ import annotations

import numpy as np

from lab_modules.exercises import Plot
from lab_modules.exercises._lqg_vs_pid_design import COLORS, LOOPS, SET_UP_CONTROLS, setups
from lab_modules.loops.radial_axis_experiment import AxisSetup
from lab_modules.loops.radial_axis_step_tests import (
    AFTER_STEP_S,
    BEFORE_STEP_S,
    column,
    loop_figures,
    step_tests,
)
from lab_modules.memo import remembered
from lab_modules.parameters import in_si
from lab_modules.plants.radial_bearing import RIG

T = RIG.sample_time_s
PLOT_POINTS = 500
NO_OVERSHOOT = "none (never reaches the reference)"   # the overshoot readout of a step that stays below


def step_tests_at(values: dict, loops: dict[str, AxisSetup]) -> dict[str, dict]:
    """Both step tests (Figs. 8-9) of both loops with the steps set on the controls."""
    return step_tests(loops, in_si(SET_UP_CONTROLS, values)["reference_step_um"], values["disturbance_step_n"])


@remembered()
def step_and_loop_figures(values: dict) -> tuple[dict, dict]:
    """Both loops' step tests (``step_tests_at``) and linear figures (``loop_figures``)."""
    loops = setups(values)
    return step_tests_at(values, loops), {name: loop_figures(axis) for name, axis in loops.items()}


def scaled(value, factor: float):
    """A readout value in display units, or the word that stands for it."""
    return value if isinstance(value, str) else value * factor


def step_readouts(tests: dict, linear: dict) -> list[tuple]:
    """Each loop's step-test figures (``tests``; one the test could not measure is a word: the rotor
    touched down, or never settled) and its two stiffness figures of the linear loop (``linear``)."""
    readouts = []
    for name in LOOPS:
        word = "touched down" if tests[name]["stops"] else "not reached"
        r = {key: (word if isinstance(value, float) and not np.isfinite(value) else value)
             for key, value in tests[name].items()}
        if not isinstance(r["reference_overshoot_percent"], str) and r["reference_overshoot_percent"] < 0:
            r["reference_overshoot_percent"] = NO_OVERSHOOT   # a negative overshoot is no figure to read
        f = linear[name]
        readouts += [
            (f"{name}: overshoot, reference step", r["reference_overshoot_percent"], "%"),
            (f"{name}: settling time (±2 %)", scaled(r["reference_settling_time_s"], 1e3), "ms"),
            (f"{name}: peak control current, reference step", r["reference_peak_current_a"], "A"),
            (f"{name}: RMS control current, reference step", r["reference_rms_current_a"], "A"),
            (f"{name}: step stiffness Δf/x_max (linear)", f["step_stiffness_n_per_m"] * 1e-6, "N/µm"),
            (f"{name}: min dynamic stiffness (linear, worst frequency)", f["min_dynamic_stiffness_n_per_m"] * 1e-6,
             "N/µm"),
            (f"{name}: frequency of the min dynamic stiffness", f["min_dynamic_stiffness_frequency_hz"], "Hz"),
            (f"{name}: largest deviation, disturbance step", scaled(r["disturbance_max_deviation_m"], 1e6), "µm"),
            (f"{name}: s_dyn of the time run (chosen plant)",
             scaled(r["disturbance_dynamic_stiffness_n_per_m"], 1e-6), "N/µm"),
            (f"{name}: offset 150 ms after the disturbance step", scaled(r["disturbance_final_offset_m"], 1e6),
             "µm"),
        ]
    return readouts


def sampled(trace: np.ndarray, name: str, rows: np.ndarray, scale: float) -> np.ndarray:
    """Column ``name`` at the given rows, scaled; NaN (a gap) past the end of a stopped run."""
    y = np.full(rows.size, np.nan)
    kept = rows < len(trace)
    y[kept] = column(trace, name)[rows[kept]] * scale
    return y


def step_plots(tests: dict, values: dict) -> list[Plot]:
    """Figs. 8-9: position and control current of both loops after each step."""
    reference_um, force_n = values["reference_step_um"], values["disturbance_step_n"]
    n_rows = round((BEFORE_STEP_S + AFTER_STEP_S) / T)
    rows = np.arange(0, n_rows, max(1, n_rows // PLOT_POINTS))
    t_ms = (rows * T - BEFORE_STEP_S) * 1e3
    plots = []
    for test, title, reference_um_after in (
            ("reference", f"Reference step {reference_um:g} µm (Fig. 8)", reference_um),
            ("disturbance", f"Disturbance step {force_n:g} N (Fig. 9)", 0.0)):
        traces = {name: tests[name][test] for name in LOOPS}
        reference = np.where(t_ms >= 0.0, reference_um_after, 0.0)
        plots.append(Plot(f"{title}: rotor position", "time after the step [ms]", "rotor position x [µm]",
                          t_ms, (("reference", reference, COLORS["reference"]),) + tuple(
                              (name, sampled(trace, "x_true_m", rows, 1e6), COLORS[name])
                              for name, trace in traces.items())))
        plots.append(Plot(f"{title}: control current", "time after the step [ms]", "coil current i [A]",
                          t_ms, tuple((name, sampled(trace, "current_a", rows, 1.0), COLORS[name])
                                      for name, trace in traces.items())))
    return plots
