"""Margins and sensitivity in the Analysis tab, as AMB engineers grade a loop.

For every loop an exercise opens at the plant input (``Exercise.open_loops``):
the open-loop Bode plot (|L| and arg L), the sensitivity |S| = 1 / |1 + L|
with the ISO 14839-3 zone limits (A < 3, B < 4, C < 5, D above), and the
readouts gain margin (up and down: the bearing is open-loop unstable, so it
is stable only between two gains), phase margin, |S|max and its zone.
"""

from __future__ import annotations

import numpy as np

from lab_modules import analysis
from lab_modules.exercises import Analysis, Exercise, Plot

COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd")
ZONE_COLORS = ("#2ca02c", "#ff7f0e", "#d62728")     # the A/B, B/C and C/D limits


def margin_view(exercise: Exercise, values: dict) -> tuple[list, list[Plot], list[str]]:
    """Readouts, plots and notes of the exercise's open loops (empty if it has none)."""
    loops = exercise.open_loops(values)
    if not loops:
        return [], [], []
    omega = analysis.frequency_grid(next(iter(loops.values())), points=400)
    readouts, magnitude, phase, sens, notes = [], [], [], [], []
    for (name, loop), color in zip(loops.items(), COLORS):
        m = analysis.loop_margins(loop, omega)
        L = analysis.open_loop_response(loop, omega)
        if np.isfinite(m.gain_margin):
            readouts.append((f"{name}: gain margin up", m.gain_margin, "×"))
        else:
            notes.append(f"{name}: the phase of L never crosses −180° above the loop's gain: no upper gain margin.")
        readouts += [(f"{name}: gain margin down", m.gain_margin_down, "×"),
                     (f"{name}: phase margin", m.phase_margin_deg, "°"),
                     (f"{name}: |S|max (zone {m.zone} of ISO 14839-3)", m.sensitivity_peak, "×")]
        magnitude.append((f"|L| {name}", np.abs(L), color))
        phase.append((f"arg L {name}", np.degrees(np.unwrap(np.angle(L))), color))
        sens.append((f"|S| {name}", 1.0 / np.abs(1.0 + L), color))
    f_hz = omega / (2 * np.pi)
    limits = tuple((f"zone limit {zone}/{chr(ord(zone) + 1)}", np.full(len(f_hz), limit), c)
                   for (zone, limit), c in zip(analysis.ISO_14839_ZONES[:3], ZONE_COLORS))
    plots = [
        Plot("Open loop L at the plant input: magnitude (|L| = 1 at the gain crossover)", "frequency [Hz]",
             "|L| [1]", f_hz, tuple(magnitude) + (("|L| = 1", np.ones(len(f_hz)), "#7f7f7f"),),
             log_x=True, log_y=True),
        Plot("Open loop L at the plant input: phase", "frequency [Hz]", "arg L [°]", f_hz, tuple(phase), log_x=True),
        Plot("Sensitivity |S| = 1/|1 + L| with the ISO 14839-3 zone limits", "frequency [Hz]", "|S| [1]", f_hz,
             tuple(sens) + limits, log_x=True),
    ]
    return readouts, plots, notes


def with_margins(result: Analysis, margins: tuple[list, list, list]) -> Analysis:
    """The analysis with the margin readouts, plots and notes appended."""
    readouts, plots, notes = margins
    return Analysis(result.readouts + readouts, result.poles, result.notes + notes, result.plots + plots)
