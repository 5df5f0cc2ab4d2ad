"""The trade-off fronts of ``lqg_vs_pid`` (paper 000, §IV, Figs. 8-9: what an LQG buys here).

Two families of designs on the linear plant with the filter and noise in use: the LQG with
the paper's weights scaled (q_x and q_v together, q_ξ apart) and the PID with its gain and
derivative time swept (and each PID as an I-PD).  Each design's step stiffness and minimum
dynamic stiffness are set against its noise-driven RMS coil current and against the peak
current a reference step costs; the fronts are the designs no other beats at no more cost.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from lab_modules import analysis, loop_responses
from lab_modules.controllers.lqr import PAPER_LQR_WEIGHTS, lqr
from lab_modules.controllers.pid import pid, setpoint_filter
from lab_modules.exercises import Plot
from lab_modules.exercises._lqg_vs_pid_design import (
    COLORS,
    LOOPS,
    SET_UP_CONTROLS,
    common_setup,
    derivative_filter_ratio,
    lqg_setup,
)
from lab_modules.loops.radial_axis_experiment import AxisSetup
from lab_modules.loops.radial_axis_step_tests import LINEAR_WINDOW_S, loop_figures
from lab_modules.parameters import in_si
from lab_modules.plants.radial_bearing import RIG

T = RIG.sample_time_s

#: LQG family: the paper's weights with q_x and q_v scaled together by one factor
#: and q_ξ by another, each over four decades (q_i, R_J as in the paper).
FRONT_LQG_FACTORS = np.geomspace(0.1, 1000.0, 9)
#: PID family: the gain K times these factors, at each derivative time T_D
#: (τ / T_D and T_I from the sliders).
FRONT_PID_GAIN_FACTORS = np.geomspace(0.25, 4.0, 13)
FRONT_PID_DERIVATIVE_TIMES_S = (0.5e-3, 1e-3, 1.5e-3, 2e-3, 3e-3, 4e-3, 6e-3)
#: A design counts on a front only if every closed-loop pole is damped at least this
#: much (lab choice): lighter damped loops ring for many periods; their step stiffness
#: looks good while their minimum dynamic stiffness collapses.  They are drawn grey.
FRONT_MIN_DAMPING = 0.15
#: The step-current front is read at this stiffness [N/m].
FRONT_STIFFNESS_TARGET_N_PER_M = 10e6


@dataclass(frozen=True)
class Designs:
    """One family of designs on the fronts: arrays of equal length."""

    step_stiffness_n_per_m: np.ndarray
    min_dynamic_stiffness_n_per_m: np.ndarray
    noise_rms_current_a: np.ndarray
    peak_current_a_per_m: np.ndarray            # reference step; for the PID family: the PID's
    peak_current_ipd_a_per_m: np.ndarray        # PID family only: the same loop as an I-PD
    min_damping: np.ndarray

    @property
    def admissible(self) -> np.ndarray:
        return self.min_damping >= FRONT_MIN_DAMPING


def _designs(rows: list[dict]) -> Designs:
    def column(name):
        return np.array([row.get(name, np.nan) for row in rows], dtype=float)
    return Designs(column("step_stiffness_n_per_m"), column("min_dynamic_stiffness_n_per_m"),
                   column("noise_rms_current_a"), column("peak_current_a_per_m"),
                   column("peak_current_ipd_a_per_m"), column("min_damping"))


#: The settings each family's front depends on (the rest move only the design markers).
_SHARED_FRONT_SETTINGS = ("filter_q_velocity", "filter_q_current", "filter_r_position", "filter_r_current",
                          "sensor_noise_um", "current_noise_a", "disturbance_force_n", "sensor_lag_us")
LQG_FRONT_SETTINGS = (*_SHARED_FRONT_SETTINGS, "integrator_input")
PID_FRONT_SETTINGS = (*_SHARED_FRONT_SETTINGS, "pid_feedback", "pid_gain", "integral_time_ms",
                      "derivative_time_ms", "derivative_filter_us")


def linear_common(names: tuple[str, ...], key: tuple) -> tuple[dict, AxisSetup]:
    """Slider values (the front's settings, the rest neutral) and the shared set-up
    on the linear plant, its filter solved once for every design of the sweep."""
    values = dict(zip(names, key))
    values.update(force_law="linear", reference_step_um=0.0, disturbance_step_n=0.0,
                  scope_excitation="reference step", step_period_ms=200.0)
    common = common_setup(values)
    _ = common.steady_state_filter
    return values, common


@lru_cache(maxsize=16)
def _lqg_front(key: tuple) -> Designs:
    values, common = linear_common(LQG_FRONT_SETTINGS, key)
    rows = []
    for factor_xv in FRONT_LQG_FACTORS:
        for factor_integral in FRONT_LQG_FACTORS:
            weights = np.array(PAPER_LQR_WEIGHTS) * (factor_xv, factor_xv, 1.0, factor_integral)
            rows.append(loop_figures(lqg_setup(common, lqr(tuple(weights), 1.0), values)))
    return _designs(rows)


@lru_cache(maxsize=16)
def _pid_front(key: tuple) -> Designs:
    values, common = linear_common(PID_FRONT_SETTINGS, key)
    rows = []
    ratio = derivative_filter_ratio(values)
    integral_time_s = in_si(SET_UP_CONTROLS, values)["integral_time_ms"]
    use_estimate, kalman_gain = values["pid_feedback"] == "estimated", common.steady_state_filter[0]
    for derivative_time_s in FRONT_PID_DERIVATIVE_TIMES_S:
        at_slider_gain = _pid(values["pid_gain"], integral_time_s, derivative_time_s, ratio * derivative_time_s)
        prefilter = _setpoint_filter(integral_time_s, derivative_time_s, ratio * derivative_time_s)
        A_c, B_c, C_c, D_c = at_slider_gain.A, at_slider_gain.B, at_slider_gain.C, at_slider_gain.D
        for factor in FRONT_PID_GAIN_FACTORS:
            # factor * C(z) scales B_c and D_c (as python-control does): the same loop as
            # common.with_changes(controller=factor * pid(...)).loop(), without its objects
            controller = analysis.Matrices(A_c, factor * B_c, C_c, factor * D_c, T)
            loop = analysis.closed_loop_matrices(common.model, controller, kalman_gain, use_estimate)
            row = loop_figures(common, loop)    # the noise is common's; the I-PD is this loop, prefiltered
            if row["min_damping"] > 0:
                ipd = analysis.with_reference_filter(loop, prefilter)
                current = loop_responses.step_response(ipd, "reference_m", round(LINEAR_WINDOW_S / T))
                row["peak_current_ipd_a_per_m"] = float(np.max(np.abs(
                    current[:, analysis.LOOP_OUTPUTS.index("current_a")])))
            rows.append(row)
    return _designs(rows)


@lru_cache(maxsize=64)
def _pid(gain: float, integral_time_s: float, derivative_time_s: float, derivative_filter_s: float
         ) -> analysis.Matrices:
    """``controllers.pid.pid``'s matrices: a move of any slider but the PID's (the filter's, the
    noise) reuses the sweep's seven (each a c2d through python-control, a tenth of the PID front's
    time).  Shared: not to be modified."""
    controller = pid(gain, integral_time_s, derivative_time_s, derivative_filter_s, T)
    return analysis.Matrices(*(np.asarray(M, dtype=float) for M in (controller.A, controller.B, controller.C,
                                                                     controller.D)), T)


@lru_cache(maxsize=64)
def _setpoint_filter(integral_time_s: float, derivative_time_s: float, derivative_filter_s: float):
    """The I-PD's reference filter (``controllers.pid.setpoint_filter``): it does not depend on the
    PID gain, so a move of the gain slider reuses the sweep's seven (each a c2d through
    python-control, a sixth of the PID front's time).  Shared: not to be modified."""
    return setpoint_filter(integral_time_s, derivative_time_s, derivative_filter_s, T)


def lqg_front(values: dict) -> Designs:
    """The LQG family on the linear plant with the current filter and noise (cached)."""
    return _lqg_front(tuple(values[name] for name in LQG_FRONT_SETTINGS))


def pid_front(values: dict) -> Designs:
    """The PID family (and its I-PD twins) on the linear plant (cached)."""
    return _pid_front(tuple(values[name] for name in PID_FRONT_SETTINGS))


def fronts(values: dict) -> tuple[Designs, Designs]:
    """Both families (a sweep takes one to two seconds; each family is cached
    per setting it depends on)."""
    return lqg_front(values), pid_front(values)


def pareto(cost: np.ndarray, stiffness: np.ndarray) -> np.ndarray:
    """Indices of the designs on the front (no other is stiffer at no more cost), by rising cost."""
    best, kept = -np.inf, []
    for k in np.argsort(cost):
        if np.isfinite(cost[k]) and stiffness[k] > best:
            best = stiffness[k]
            kept.append(k)
    return np.array(kept, dtype=int)


def stiffness_at(cost: np.ndarray, stiffness: np.ndarray, level: float) -> float:
    """Stiffness on the front at the given cost (linear in log cost between
    front designs); NaN outside the swept range."""
    k = pareto(cost, stiffness)
    if k.size == 0 or not cost[k[0]] <= level <= cost[k[-1]]:
        return float("nan")
    return float(np.interp(np.log(level), np.log(cost[k]), stiffness[k]))


def cost_of(cost: np.ndarray, stiffness: np.ndarray, target: float) -> float:
    """Least cost on the front for the target stiffness (log-linear between the
    front designs either side of it); NaN if the family never reaches it."""
    k = pareto(cost, stiffness)
    above = np.flatnonzero(stiffness[k] >= target)
    if above.size == 0:
        return float("nan")
    j = above[0]
    if j == 0:
        return float(cost[k[0]])
    (c0, c1), (s0, s1) = cost[k[j - 1:j + 1]], stiffness[k[j - 1:j + 1]]
    return float(np.exp(np.log(c0) + (target - s0) / (s1 - s0) * (np.log(c1) - np.log(c0))))


def front_figures(values: dict, pid_noise_a: float) -> dict[str, float]:
    """What the fronts say, as numbers: the LQG/PID step-stiffness ratio at the
    PID design's RMS noise current, and the least peak current on the
    reference step that reaches ``FRONT_STIFFNESS_TARGET_N_PER_M`` per family."""
    lqg, pid_family = fronts(values)
    step_m = in_si(SET_UP_CONTROLS, values)["reference_step_um"]
    L, Pf = lqg.admissible, pid_family.admissible
    return {
        "stiffness_ratio_at_equal_noise":
            stiffness_at(lqg.noise_rms_current_a[L], lqg.step_stiffness_n_per_m[L], pid_noise_a)
            / stiffness_at(pid_family.noise_rms_current_a[Pf], pid_family.step_stiffness_n_per_m[Pf], pid_noise_a),
        "min_dynamic_stiffness_ratio_at_equal_noise":
            stiffness_at(lqg.noise_rms_current_a[L], lqg.min_dynamic_stiffness_n_per_m[L], pid_noise_a)
            / stiffness_at(pid_family.noise_rms_current_a[Pf], pid_family.min_dynamic_stiffness_n_per_m[Pf],
                           pid_noise_a),
        **{f"peak_current_for_target_{name}_a": cost_of(peak[ok] * step_m, stiffness[ok],
                                                       FRONT_STIFFNESS_TARGET_N_PER_M)
           for name, peak, stiffness, ok in (
               ("lqg", lqg.peak_current_a_per_m, lqg.step_stiffness_n_per_m, L),
               ("pid", pid_family.peak_current_a_per_m, pid_family.step_stiffness_n_per_m, Pf),
               ("ipd", pid_family.peak_current_ipd_a_per_m, pid_family.step_stiffness_n_per_m, Pf))},
    }


FRONT_COLORS = {"LQG": COLORS["LQG"], "PID": COLORS["PID"], "I-PD": "#2ca02c", "rings": "#c7c7c7",
                "LQG in use": "#5c0000", "PID in use": "#08306b"}
RINGS = f"ζ < {FRONT_MIN_DAMPING:g} (rings)"
#: Series (label, colour) of the front plots, in order.
FRONT_SERIES = {
    "noise": (("LQG designs", FRONT_COLORS["LQG"]), ("PID designs", FRONT_COLORS["PID"]),
              (RINGS, FRONT_COLORS["rings"]), ("LQG in use", FRONT_COLORS["LQG in use"]),
              ("PID in use", FRONT_COLORS["PID in use"])),
    "current": (("LQG designs", FRONT_COLORS["LQG"]), ("PID designs", FRONT_COLORS["PID"]),
                ("I-PD designs", FRONT_COLORS["I-PD"]), (RINGS, FRONT_COLORS["rings"]),
                ("LQG in use", FRONT_COLORS["LQG in use"]), ("PID in use", FRONT_COLORS["PID in use"])),
}


def scatter(title: str, x_label: str, y_label: str,
            groups: list[tuple[str, np.ndarray, np.ndarray, str]]) -> Plot:
    """A scatter plot of several point sets over one shared, sorted x axis
    (each set a series with gaps where the others have their points); points
    with a non-positive or non-finite x or y are left out (log x axis)."""
    kept = []
    for label, x, y, color in groups:
        x, y = np.atleast_1d(np.asarray(x, dtype=float)), np.atleast_1d(np.asarray(y, dtype=float))
        ok = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
        kept.append((label, x[ok], y[ok], color))
    xs = np.concatenate([x for _, x, _, _ in kept])
    if xs.size == 0:                                   # nothing yet: an empty frame on the same axes
        return Plot(title, x_label, y_label, np.array([0.1, 1.0]),
                    tuple((label, np.full(2, np.nan), color) for label, _, _, color in kept),
                    points=True, log_x=True)
    order = np.argsort(xs, kind="stable")
    series, start = [], 0
    for label, x, y, color in kept:
        column = np.full(xs.size, np.nan)
        column[start:start + x.size] = y
        start += x.size
        series.append((label, column[order], color))
    return Plot(title, x_label, y_label, xs[order], tuple(series), points=True, log_x=True)


def front_plots(values: dict, linear: dict[str, dict] | None) -> list[Plot]:
    """The trade-off fronts (Analysis tab): (a) step stiffness against the
    noise-driven RMS coil current, (b) step stiffness against the peak coil
    current on the reference step, (c) minimum dynamic stiffness against the
    RMS noise current; every swept design, the lightly damped ones grey, the
    designs in use marked.  ``linear`` None: the empty frames (still computing)."""
    step_m = in_si(SET_UP_CONTROLS, values)["reference_step_um"]
    titles = ("Trade-off front (a): step stiffness against noise current",
              f"Trade-off front (b): step stiffness against peak current, {values['reference_step_um']:g} µm step",
              "Trade-off front (c): minimum dynamic stiffness against noise current")
    noise_label = "noise-driven RMS coil current [A]"
    current_label = "peak coil current on the reference step [A]"
    # y labels of at most ~20 characters: a 1024 x 768 window draws these charts about 180 px high
    step_label, dynamic_label = "Δf/x_max [N/µm]", "min stiffness [N/µm]"
    empty = np.zeros(0)
    if linear is None:                      # same series and colours: the browser keeps the first ones
        return [scatter(title, x_label, y_label, [(label, empty, empty, color) for label, color in series])
                for title, x_label, y_label, series in (
                    (titles[0], noise_label, step_label, FRONT_SERIES["noise"]),
                    (titles[1], current_label, step_label, FRONT_SERIES["current"]),
                    (titles[2], noise_label, dynamic_label, FRONT_SERIES["noise"]))]
    lqg, pid_family = fronts(values)
    L, Pf = lqg.admissible, pid_family.admissible

    def per_um(stiffness):
        return np.asarray(stiffness) * 1e-6

    def noise_front(stiffness_of, key):
        return [
            ("LQG designs", lqg.noise_rms_current_a[L], per_um(stiffness_of(lqg)[L]), FRONT_COLORS["LQG"]),
            ("PID designs", pid_family.noise_rms_current_a[Pf], per_um(stiffness_of(pid_family)[Pf]),
             FRONT_COLORS["PID"]),
            (RINGS,
             np.r_[lqg.noise_rms_current_a[~L], pid_family.noise_rms_current_a[~Pf]],
             per_um(np.r_[stiffness_of(lqg)[~L], stiffness_of(pid_family)[~Pf]]), FRONT_COLORS["rings"]),
            *((f"{name} in use", linear[name]["noise_rms_current_a"], per_um(linear[name][key]),
               FRONT_COLORS[f"{name} in use"]) for name in LOOPS)]

    current = [
        ("LQG designs", lqg.peak_current_a_per_m[L] * step_m, per_um(lqg.step_stiffness_n_per_m[L]),
         FRONT_COLORS["LQG"]),
        ("PID designs", pid_family.peak_current_a_per_m[Pf] * step_m, per_um(pid_family.step_stiffness_n_per_m[Pf]),
         FRONT_COLORS["PID"]),
        ("I-PD designs", pid_family.peak_current_ipd_a_per_m[Pf] * step_m,
         per_um(pid_family.step_stiffness_n_per_m[Pf]), FRONT_COLORS["I-PD"]),
        (RINGS,
         np.r_[lqg.peak_current_a_per_m[~L], pid_family.peak_current_a_per_m[~Pf]] * step_m,
         per_um(np.r_[lqg.step_stiffness_n_per_m[~L], pid_family.step_stiffness_n_per_m[~Pf]]),
         FRONT_COLORS["rings"]),
        *((f"{name} in use", linear[name]["peak_current_a_per_m"] * step_m,
           per_um(linear[name]["step_stiffness_n_per_m"]), FRONT_COLORS[f"{name} in use"]) for name in LOOPS)]
    return [scatter(titles[0], noise_label, step_label,
                    noise_front(lambda d: d.step_stiffness_n_per_m, "step_stiffness_n_per_m")),
            scatter(titles[1], current_label, step_label, current),
            scatter(titles[2], noise_label, dynamic_label,
                    noise_front(lambda d: d.min_dynamic_stiffness_n_per_m, "min_dynamic_stiffness_n_per_m"))]
