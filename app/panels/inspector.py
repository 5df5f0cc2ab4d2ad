"""The filter inspector: while the simulation is paused, step it one sample at a time
and read the Kalman filter's numbers at that sample.

Shown for every exercise whose simulation offers ``filter_state()`` (see
``exercises.Simulation``): the corrected estimate x̂ with ±σ = √P_ii per state,
the correlations P_ij / (σ_i σ_j), the gain K (state per measurement unit) and
each measurement's innovation ν with its predicted σ = √S_jj and their ratio
(|ν/√S| above 3 is a rare event for a consistent filter).  Numbers are shown
with an SI prefix chosen per row, so x̂ and its σ share one unit, in the lab's
one number format (``lab_modules.formatting``) with 4 significant digits.
"""

from __future__ import annotations

import math

import numpy as np
import viser

from lab_modules.formatting import number, signed

PREFIXES = ((1e9, "G"), (1e6, "M"), (1e3, "k"), (1.0, ""), (1e-3, "m"), (1e-6, "µ"), (1e-9, "n"), (1e-12, "p"))
#: units an SI prefix can go in front of (others, and pure numbers, keep their unit)
PREFIXABLE = ("m", "m/s", "A", "V", "N", "N/A", "N/m", "H", "s")
DIGITS = 4                        # one more than a readout: a filter is debugged digit by digit
RUNNING_NOTE = "*Pause the simulation (or press Step) to inspect the filter at one sample.*"


def available(simulation) -> bool:
    return callable(getattr(simulation, "filter_state", None))


def prefixed(scale_of: float, unit: str) -> tuple[float, str]:
    """(divisor, unit with prefix) for numbers of about ``scale_of`` in ``unit``: the largest
    prefix that keeps them at or above 1 (µm, mm/s, kN/m ...); no prefix for other units."""
    if unit not in PREFIXABLE or not np.isfinite(scale_of) or scale_of == 0:
        return 1.0, unit
    for factor, prefix in PREFIXES:
        if abs(scale_of) >= factor * 0.9995:
            return factor, prefix + unit
    return PREFIXES[-1][0], PREFIXES[-1][1] + unit


def symbol(label: str) -> str:
    """The state's symbol: the last word of its label ('position x' -> 'x')."""
    return label.split()[-1] if "(" not in label else label.split("(")[0].split()[-1]


def gain_unit(gain: float, unit: str, y_unit: str) -> tuple[float, str]:
    """(divisor, unit) of one gain entry: state unit per measurement unit, cancelled where
    they share it (m per m: a pure number; (m/s) per m: 1/s), else with an SI prefix."""
    if unit == y_unit:
        return 1.0, ""
    if unit.startswith(y_unit + "/"):
        return 1.0, "1/" + unit[len(y_unit) + 1:]
    factor, shown = prefixed(abs(gain), unit)
    return factor, f"{shown}/{y_unit}" if "/" not in shown else f"({shown})/{y_unit}"


def markdown(state: dict | None, sample_time_s: float) -> str:
    """The inspector's text for one ``filter_state()`` result (None: the last advance was no single step)."""
    if state is None:
        return ("*Press Step one sample: the filter is shown at that sample (the simulations keep "
                "the filter's numbers only for single steps, so running costs nothing extra).*")
    x, P = np.asarray(state["x"], dtype=float), np.asarray(state["P"], dtype=float)
    sigma = np.sqrt(np.clip(np.diag(P), 0.0, None))
    t = state["time_s"]
    title = state["title"][:1].upper() + state["title"][1:]
    lines = [(f"**{title}** at t = {t * 1e3:.3f} ms (sample {round(t / sample_time_s)}), "
              "after the correction with this sample's measurement."), "",
             "| state | x̂ | ±σ = √P_ii | unit |", "|---|---:|---:|---|"]
    for (label, unit), value, s in zip(state["states"], x, sigma):
        factor, shown = prefixed(max(abs(value), s), unit)
        lines.append(f"| {label} | {number(value / factor, DIGITS)} | {number(s / factor, DIGITS)} "
                     f"| {shown} |")
    names = [symbol(label) for label, _ in state["states"]]
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = P / np.outer(sigma, sigma)
    lines += ["", "Correlations ρ_ij = P_ij / (σ_i σ_j):", "",
              "| ρ | " + " | ".join(names) + " |", "|---|" + "---:|" * len(names)]
    for name, row in zip(names, rho):
        lines.append(f"| {name} | " + " | ".join(signed(r) for r in row) + " |")
    if state.get("K") is None:
        lines += ["", "*This filter corrects continuously (no per-sample gain or innovation).*"]
        return "\n".join(lines)
    K = np.atleast_2d(np.asarray(state["K"], dtype=float))
    measurements = state["measurements"]
    lines += ["", "Kalman gain K (state change per unit of innovation):", "",
              "| K | " + " | ".join(label for label, _ in measurements) + " |", "|---|" + "---:|" * len(measurements)]
    for (label, unit), row in zip(state["states"], K):
        cells = [f"{number(gain / factor, DIGITS)} {shown}".strip()
                 for gain, (_, y_unit) in zip(row, measurements)
                 for factor, shown in [gain_unit(gain, unit, y_unit)]]
        lines.append(f"| {symbol(label)} | " + " | ".join(cells) + " |")
    lines += ["", "| measurement | innovation ν | predicted σ = √S | ν/√S |", "|---|---:|---:|---:|"]
    for (label, unit), nu, s in zip(measurements, state["innovation"], state["innovation_sigma"]):
        factor, shown = prefixed(max(abs(nu), s), unit)
        ratio = nu / s if s > 0 else math.nan
        lines.append(f"| {label} | {number(nu / factor, DIGITS)} {shown} "
                     f"| {number(s / factor, DIGITS)} {shown} | {signed(ratio)} |")
    return "\n".join(lines)


class FilterInspector:
    """The "Filter inspector" folder in the controls: a Step button and the filter's numbers."""

    def __init__(self, gui, on_step):
        with gui.add_folder("Filter inspector", expand_by_default=False):
            step = gui.add_button("Step one sample", icon=viser.Icon.PLAYER_TRACK_NEXT,
                                  hint="Pauses the simulation and runs one sample: sensors, filter correction, "
                                       "controller, prediction, plant.")
            step.on_click(on_step)
            self.text = gui.add_markdown(RUNNING_NOTE)

    @classmethod
    def add(cls, gui, simulation, on_step) -> FilterInspector | None:
        """The inspector for ``simulation`` (None if it has no filter to inspect); ``on_step`` is
        the Step button's callback."""
        return cls(gui, on_step) if available(simulation) else None

    def show(self, running: bool, simulation) -> None:
        """The filter at the newest sample while paused (call holding the tab's GUI lock)."""
        state = simulation.filter_state() if not running and available(simulation) else None
        self.text.content = RUNNING_NOTE if running else markdown(state, simulation.sample_time_s)
