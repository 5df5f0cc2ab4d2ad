"""What a headless tab of the load bench does besides watching (``app.commands.load_bench``):
which slider it moves between two values and which readout row answers a move, and with
``--mix`` which exercise and panel tab it shows.

By default every tab moves kalman_noise's position-noise slider (``KALMAN_NOISE_MOVE``).  With
``--mix`` the tabs are spread over every exercise (each switches to its own after the lab opens)
and over the panel tabs (``PANEL_MIX``: half on the Scope, the others on the Pole map or the
Analysis tab, reported as the browser's beacon does); each moves a control its exercise's Scope
readouts depend on (``mix_move``)."""

from __future__ import annotations

import re
from dataclasses import dataclass

from app.panels.text import cell
from lab_modules.exercises import SCOPE, get, results
from lab_modules.memo import ReadValues

#: With ``--mix``, the panel tab the k-th tab shows (its exercise: the k-th of the lab's, in turn)
PANEL_MIX = ("Scope", "Pole map", "Scope", "Analysis")
MIX_RUN_S = 0.3                 # simulated seconds a mix tab's moved setting must run without stopping


@dataclass(frozen=True)
class SliderMove:
    """The slider a tab moves (its label's start) between two values, and the readout row
    (``| label | value |``, the value as group 1) whose change answers a move."""

    label: str
    values: tuple[float, float]
    readout_row: re.Pattern


#: kalman_noise's position-noise slider; an analysis readout that a move changes: the time from a move to its
#: new value in the tab is the slider-to-readout latency (the scope-window rows change anyway)
KALMAN_NOISE_MOVE = SliderMove("Position sensor noise", (1.33, 2.0),
                               re.compile(r"RMS displacement, measured feedback \| *([^|]+?) *\|"))
NO_MOVE = SliderMove("", (0.0, 0.0), re.compile(r"(?!)"))   # no slider found: the tab only watches


def mix_move(exercise_name: str) -> SliderMove:
    """The first plain numeric slider the exercise's Scope readouts read with two values 10 % (or 2 %
    of its range) apart, from its default or else from the middle of its range, at which the
    simulation keeps running (a stopped run sends no scope updates) and a readout differs; that
    readout answers a move."""
    exercise = get(exercise_name)
    values = exercise.resolve({})

    def scope_readouts(at: dict) -> tuple[list, set]:
        read = ReadValues(at)
        *_, last = results(exercise.analyse_panel(read, SCOPE))
        return last.readouts, read.read

    def runs(at: dict) -> bool:
        simulation = exercise.simulation(at)
        simulation.advance(round(MIX_RUN_S / simulation.sample_time_s))
        return not simulation.status_message()
    _, read = scope_readouts(values)
    for parameter in exercise.parameters:
        if parameter.choices or parameter.log or parameter.integer or parameter.name not in read:
            continue
        low, high = exercise.parameter_ranges(values).get(parameter.name, (parameter.minimum, parameter.maximum))
        for start in (float(parameter.default), 0.5 * (low + high)):
            moved = float(f"{min(max(1.1 * start if start else low + 0.02 * (high - low), low), high):.4g}")
            pair = [{**values, parameter.name: value} for value in (start, moved)]
            if not all(runs(at) for at in pair):
                continue
            (before, _), (after, _) = (scope_readouts(at) for at in pair)
            changed = next((label for (label, a, _), (_, b, _) in zip(before, after) if a != b), None)
            if changed is not None:
                label = f"{parameter.label} [{parameter.unit}]" if parameter.unit else parameter.label
                return SliderMove(label, (start, moved), re.compile(re.escape(cell(changed)) + r" \| *([^|]+?) *\|"))
    return NO_MOVE
