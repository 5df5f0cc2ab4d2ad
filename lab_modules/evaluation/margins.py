"""Margins and sensitivity of an exercise's loops, as AMB engineers grade a loop; the
Analysis tab shows the readouts and draws the plots.

For every loop an exercise opens at the plant input (``Exercise.open_loops``):
the open-loop Bode plot (|L| and arg L), the sensitivity |S| = 1 / |1 + L|
in dB, as AMB engineers read it, with the ISO 14839-3 zone limits (A < 3 = 9.5 dB,
B < 4 = 12 dB, C < 5 = 14 dB, D above), and the
readouts gain margin (up and down: the bearing is open-loop unstable, so it
is stable only between two gains), phase margin, |S|max and its zone.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from lab_modules.exercises import Analysis, Exercise, Plot
from lab_modules.loop_sensitivity import (
    ISO_14839_ZONES,
    Margins,
    frequency_grid,
    loop_margins,
    open_loop_response,
)

COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd")
ZONE_COLORS = ("#2ca02c", "#ff7f0e", "#d62728")     # the A/B, B/C and C/D limits
#: Frequencies the margins are searched on (the plots use fewer): dense enough that the lightly
#: damped bending modes of ``sensor_placement`` cannot slip between two points.
MARGIN_GRID_POINTS = 3000


class MarginView(NamedTuple):
    """What the margins of an exercise's open loops add to its analysis."""

    readouts: list[tuple[str, float, str]]            # (label, value, unit), as ``Analysis.readouts``
    plots: list[Plot]                                 # |L|, arg L and |S| [dB] with the ISO zone limits
    notes: list[str]                                  # what the student reads below the readouts


def margin_view(exercise: Exercise, values: dict) -> MarginView:
    """Readouts, plots and notes of the exercise's open loops (empty if it has none)."""
    loops = exercise.open_loops(values)
    if not loops:
        return MarginView([], [], [exercise.no_feedback_loop] if exercise.no_feedback_loop else [])
    found = {name: loop_margins(loop, frequency_grid(loop, points=MARGIN_GRID_POINTS))
             for name, loop in loops.items()}
    # the plots' grid, plus each loop's |S| peak and crossover: a narrow resonance peak is drawn at its height
    extra = [w for m in found.values() for w in (m.sensitivity_peak_rad_s, m.gain_crossover_rad_s) if np.isfinite(w)]
    omega = np.unique(np.concatenate([frequency_grid(next(iter(loops.values())), points=400), extra]))
    readouts, magnitude, phase, sens, notes = [], [], [], [], []
    for (name, loop), color in zip(loops.items(), COLORS):
        m = found[name]
        L = open_loop_response(loop, omega)
        readouts += _margin_readouts(name, m)
        if not np.isfinite(m.gain_margin):
            notes.append(f"{name}: the phase of L never crosses −180° above the loop's gain: no upper gain margin.")
        if not m.stable:
            notes.append(f"{name}: the closed loop is unstable at these settings (zone D); " + (
                "the gain margins say by which factor the loop gain would have to change to become stable."
                if np.isfinite(m.gain_margin) or m.gain_margin_down > 0 else
                "no change of the loop gain alone makes it stable."))
        magnitude.append((f"|L| {name}", np.abs(L), color))
        phase.append((f"arg L {name}", np.degrees(np.unwrap(np.angle(L))), color))
        sens.append((f"|S| {name}", _decibels_of(1.0 / np.abs(1.0 + L)), color))
    f_hz = omega / (2 * np.pi)
    limits = tuple((f"zone limit {zone}/{chr(ord(zone) + 1)} ({limit:g}×)", np.full(len(f_hz), _decibels(limit)), c)
                   for (zone, limit), c in zip(ISO_14839_ZONES[:3], ZONE_COLORS))
    plots = [
        Plot("Open loop L at the plant input: magnitude (|L| = 1 at the gain crossover)", "frequency [Hz]",
             "|L| [1]", f_hz, tuple(magnitude) + (("|L| = 1", np.ones(len(f_hz)), "#7f7f7f"),),
             log_x=True, log_y=True),
        Plot("Open loop L at the plant input: phase", "frequency [Hz]", "arg L [°]", f_hz, tuple(phase), log_x=True),
        Plot("Sensitivity |S| = 1/|1 + L|, ISO 14839-3 zones A < 9.5 < B < 12 < C < 14 dB < D",
             "frequency [Hz]", "|S| [dB]", f_hz,
             tuple(sens) + limits, log_x=True),
    ]
    return MarginView(readouts, plots, notes)


def _decibels(factor: float) -> float:
    return float(20.0 * np.log10(factor)) if factor > 0 else -np.inf


def _decibels_of(factors: np.ndarray) -> np.ndarray:
    """20 log10 of each factor (a zero, |S| at an open-loop pole on the jω axis, is a gap: NaN)."""
    factors = np.asarray(factors, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(factors > 0, 20.0 * np.log10(np.where(factors > 0, factors, 1.0)), np.nan)


def _margin_readouts(name: str, m: Margins) -> list[tuple[str, float, str]]:
    """Gain margins as factors and in dB, phase margin, gain crossover, |S|max and its ISO zone."""
    rows = []
    if np.isfinite(m.gain_margin):
        rows += [(f"{name}: gain margin up", m.gain_margin, "×"),
                 (f"{name}: gain margin up", _decibels(m.gain_margin), "dB")]
    if m.gain_margin_down > 0:
        rows += [(f"{name}: gain margin down", m.gain_margin_down, "×"),
                 (f"{name}: gain margin down", _decibels(m.gain_margin_down), "dB")]
    rows += [(f"{name}: phase margin", m.phase_margin_deg, "°"),
             (f"{name}: gain crossover frequency", m.gain_crossover_rad_s / (2 * np.pi), "Hz"),
             (f"{name}: |S|max, ISO 14839-3 zone {m.zone}", m.sensitivity_peak, "×"),
             (f"{name}: |S|max, ISO 14839-3 zone {m.zone}", _decibels(m.sensitivity_peak), "dB")]
    return rows


def with_margins(result: Analysis, margins: MarginView) -> Analysis:
    """The analysis with the margin readouts, plots and notes appended."""
    readouts, plots, notes = margins
    return Analysis(result.readouts + readouts, result.poles, result.notes + notes, result.plots + plots)
