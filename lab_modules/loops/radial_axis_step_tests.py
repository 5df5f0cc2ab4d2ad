"""Step tests and stiffness of one loop of the bearing axis (paper 000, §IV, Figs. 8-9).

Time runs: noise-free runs of the compiled loop (``AxisSimulation``) on the set-up's plant
(nonlinear eq. 10 or linear eq. 3), a reference or disturbance step at t = 0 after
``BEFORE_STEP_S`` at rest, observed for ``AFTER_STEP_S``; the figures of each step
(overshoot, settling time in a ±``SETTLING_BAND`` band, peak and RMS coil current, the
dynamic stiffness s_dyn = Δf_z / Δx_max of §IV) and the largest disturbance step a loop
holds.  Linear figures: the same loop on the linear plant with the steady-state filter
(``AxisSetup.loop``), stiffness in two definitions (step and minimum over frequency),
noise-driven RMS values by the Lyapunov equation.
"""

from __future__ import annotations

import numpy as np

from lab_modules import analysis, loop_responses
from lab_modules.loops.radial_axis_experiment import AxisSetup, AxisSimulation
from lab_modules.loops.radial_axis_loop import TRACE_COLUMNS
from lab_modules.plants.radial_bearing import RIG

T = RIG.sample_time_s
#: Step test (Figs. 8-9): rest before the step, observation after it, settling band.
BEFORE_STEP_S, AFTER_STEP_S, SETTLING_BAND = 5e-3, 0.15, 0.02
#: Linear step responses run longer: with a weak integral the deflection peaks late.
LINEAR_WINDOW_S = 0.3
#: Largest disturbance step: searched up to this force, to this resolution.
LARGEST_STEP_TRIED_N, LARGEST_STEP_RESOLUTION_N = 1000.0, 5.0


def step_response(axis: AxisSetup, reference_m: float, force_n: float) -> tuple[np.ndarray, str]:
    """Noise-free response of one loop to a step at t = 0: rows (t [s], TRACE_COLUMNS)
    from -``BEFORE_STEP_S`` to ``AFTER_STEP_S``, and the stop message ('' if none)."""
    period = 2.0 * (BEFORE_STEP_S + AFTER_STEP_S)          # the square wave switches on at period / 2
    quiet = axis.with_changes(sensor_noise_m=0.0, current_noise_a=0.0, process_force_n=0.0,
                              process_current_a=0.0, reference_step_m=reference_m,
                              disturbance_step_n=force_n, step_period_s=period)
    sim = AxisSimulation(quiet)
    sim.step = round(AFTER_STEP_S / T)
    trace = sim.advance(round((BEFORE_STEP_S + AFTER_STEP_S) / T))
    trace[:, 0] -= 0.5 * period
    return trace, sim.status_message()


def column(trace: np.ndarray, name: str) -> np.ndarray:
    """One of ``TRACE_COLUMNS`` of a trace."""
    return trace[:, 1 + TRACE_COLUMNS.index(name)]


def reference_step_figures(trace: np.ndarray, step_m: float) -> dict[str, float]:
    """Overshoot [%], settling time [s] (±2 % band), peak and RMS coil current [A] after the step."""
    after = trace[trace[:, 0] >= 0.0]
    x, current = column(after, "x_true_m"), column(after, "current_a")
    outside = np.flatnonzero(np.abs(x - step_m) > SETTLING_BAND * abs(step_m))
    complete = len(after) >= round(AFTER_STEP_S / T)
    if not complete or outside.size and outside[-1] == len(x) - 1:
        settling = float("nan")
    else:
        settling = float(after[outside[-1] + 1, 0]) if outside.size else 0.0
    return {"overshoot_percent": 100.0 * (np.max(x / step_m) - 1.0) if complete else float("nan"),
            "settling_time_s": settling,
            "peak_current_a": float(np.max(np.abs(current))),
            "rms_current_a": float(np.sqrt(np.mean(current**2)))}


def disturbance_step_figures(trace: np.ndarray, force_n: float) -> dict[str, float]:
    """Largest deviation [m] from the (zero) reference, s_dyn = |Δf_z| / Δx_max [N/m],
    the offset [m] left at the end of the window and the peak coil current [A] after the step."""
    after = trace[trace[:, 0] >= 0.0]
    x = column(after, "x_true_m")
    complete = len(after) >= round(AFTER_STEP_S / T)
    deviation = float(np.max(np.abs(x))) if complete else float("nan")
    return {"max_deviation_m": deviation, "dynamic_stiffness_n_per_m": abs(force_n) / deviation,
            "final_offset_m": float(x[-1]) if complete else float("nan"),
            "peak_current_a": float(np.max(np.abs(column(after, "current_a"))))}


def step_tests(loops: dict[str, AxisSetup], reference_m: float, force_n: float) -> dict[str, dict]:
    """Both step tests (reference ``reference_m`` [m], disturbance ``force_n`` [N]) for each loop:
    traces, figures (prefixed ``reference_``, ``disturbance_``) and stop messages."""
    results = {}
    for name, axis in loops.items():
        reference_trace, reference_stop = step_response(axis, reference_m, 0.0)
        force_trace, force_stop = step_response(axis, 0.0, force_n)
        results[name] = {"reference": reference_trace, "disturbance": force_trace,
                         "stops": [m for m in (reference_stop, force_stop) if m],
                         **{f"reference_{k}": v for k, v in reference_step_figures(reference_trace,
                                                                                   reference_m).items()},
                         **{f"disturbance_{k}": v for k, v in disturbance_step_figures(force_trace,
                                                                                       force_n).items()}}
    return results


def largest_disturbance_step(axis: AxisSetup, upper_n: float = LARGEST_STEP_TRIED_N,
                             resolution_n: float = LARGEST_STEP_RESOLUTION_N) -> float:
    """Largest disturbance step [N] up to ``upper_n`` that the loop holds for the
    step test's 150 ms without touchdown (noise-free, chosen plant), by bisection
    to ``resolution_n``.  On the nonlinear plant the force law eq. 10 softens
    with the deflection, so a loop that is stable for small steps can still
    lose the rotor on a large one."""
    def holds(force_n: float) -> bool:
        return step_response(axis, 0.0, force_n)[1] == ""

    if holds(upper_n):
        return upper_n
    low, high = 0.0, upper_n
    while high - low > resolution_n:
        middle = 0.5 * (low + high)
        low, high = (middle, high) if holds(middle) else (low, middle)
    return low


# -- two stiffness definitions on the linear loop ---------------------------------------

def linear_figures(loop: analysis.Loop) -> dict[str, float]:
    """The loop's figures on the linear plant with the steady-state filter
    (python-control-style system of ``analysis.closed_loop``):

    * ``step_stiffness_n_per_m``: |Δf| / largest deflection after a force step
      (paper 000 §IV, Fig. 9's s_dyn, here over ``LINEAR_WINDOW_S``);
    * ``min_dynamic_stiffness_n_per_m`` and ``..._frequency_hz``: the smallest
      |F/X(jω)| over frequency (the ISO 14839 style figure: a sinusoidal force
      at the worst frequency);
    * ``overshoot_percent``, ``peak_current_a_per_m`` (peak coil current per
      metre of reference step: linear, so scale by the step), ``settling_time_s``
      (±2 %) of a reference step;
    * ``min_damping``: the smallest damping ratio ζ among the loop's poles
      (1 for none complex; ≤ 0 unstable).

    Unstable loops return NaN figures (and their ``min_damping``)."""
    poles = analysis.z_to_s(analysis.loop_poles(loop), T)
    damping = float(np.min(-poles.real / np.maximum(np.abs(poles), 1e-300)))
    nan = float("nan")
    if not np.all(poles.real < 0):
        return {"step_stiffness_n_per_m": nan, "min_dynamic_stiffness_n_per_m": nan,
                "min_dynamic_stiffness_frequency_hz": nan, "overshoot_percent": nan,
                "peak_current_a_per_m": nan, "settling_time_s": nan, "min_damping": damping}
    n = round(LINEAR_WINDOW_S / T)
    x_index, i_index = analysis.LOOP_OUTPUTS.index("x_m"), analysis.LOOP_OUTPUTS.index("current_a")
    force, reference = loop_responses.step_responses(loop, ("disturbance_n", "reference_m"), n)
    force = force[:, x_index]
    x = reference[:, x_index]
    outside = np.flatnonzero(np.abs(x - 1.0) > SETTLING_BAND)
    compliance, frequency = loop_responses.peak_gain(loop, "disturbance_n", "x_m")
    return {"step_stiffness_n_per_m": 1.0 / float(np.max(np.abs(force))),
            "min_dynamic_stiffness_n_per_m": 1.0 / compliance,
            "min_dynamic_stiffness_frequency_hz": frequency,
            "overshoot_percent": 100.0 * (float(np.max(x)) - 1.0),
            "peak_current_a_per_m": float(np.max(np.abs(reference[:, i_index]))),
            "settling_time_s": (outside[-1] + 1) * T if outside.size else 0.0,
            "min_damping": damping}


def loop_figures(axis: AxisSetup, loop: analysis.Loop | None = None) -> dict[str, float]:
    """``linear_figures`` of one set-up plus its noise-driven RMS coil current [A]
    and rotor displacement [m] (Lyapunov, ``analysis.noise_rms``); ``loop``: the set-up's
    ``axis.loop()`` if the caller has built it already."""
    loop = axis.loop() if loop is None else loop
    figures = linear_figures(loop)
    rms = analysis.noise_rms(loop, axis.noise_variances)
    return {**figures, "noise_rms_current_a": float(rms["current_a"]), "noise_rms_x_m": float(rms["x_m"])}
