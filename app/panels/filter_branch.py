"""The filter debugger's branch in time: a scope of one state around the shown sample, the
original filter solid and the branch dashed (estimate and ±3σ band), the true state, and a
vertical line at the shown sample; and what keeping a branch sets.

A branch is kept by the exercise's own controls: the parameters named ``filter_q_*`` scaled by
the branch's Q factor and ``filter_r_*`` by its R factor, kept only when a simulation at those
values has exactly the branch's Q and R (an exercise whose Q is not its ``filter_q_*`` controls
alone - a preset, the plant's own noise - says so instead)."""

from __future__ import annotations

import numpy as np
import viser

from app.panels.inspector import prefixed
from lab_modules.estimators.filter_history import FilterHistory, FilterModel
from lab_modules.formatting import number
from lab_modules.parameters import ParameterError

ORIGINAL_COLOUR, BRANCH_COLOUR, TRUTH_COLOUR, MARK_COLOUR = "#1f77b4", "#ff7f0e", "#2ca02c", "#555555"
BEFORE = 200                     # samples shown before the shown one
AFTER = 400                      # samples shown after it (the branch's horizon by default)


_PLAIN = {"points": viser.uplot.Series_Points(show=False)}
_DASHED = {"dash": (6.0, 4.0), **_PLAIN}
#: The overlay's series (fixed, so that a new sample or branch changes only the data).
SERIES = (viser.uplot.Series(label="t − t_shown [ms]"),
          viser.uplot.Series(label="x̂⁺", stroke=ORIGINAL_COLOUR, width=1.5, **_PLAIN),
          viser.uplot.Series(label="±3σ", stroke=ORIGINAL_COLOUR, width=0.75, **_PLAIN),
          viser.uplot.Series(label="", stroke=ORIGINAL_COLOUR, width=0.75, **_PLAIN),
          viser.uplot.Series(label="true", stroke=TRUTH_COLOUR, width=1.0, **_PLAIN),
          viser.uplot.Series(label="branch x̂⁺", stroke=BRANCH_COLOUR, width=2.0, **_DASHED),
          viser.uplot.Series(label="branch ±3σ", stroke=BRANCH_COLOUR, width=1.0, **_DASHED),
          viser.uplot.Series(label="", stroke=BRANCH_COLOUR, width=1.0, **_DASHED),
          viser.uplot.Series(label="shown sample", stroke=MARK_COLOUR, width=1.5, **_PLAIN))


def overlay_chart(history: FilterHistory, row: int, state: int, rerun: FilterHistory | None,
                  after: int = AFTER) -> tuple[tuple, dict]:
    """uPlot data and options: state ``state``'s x̂⁺ ± 3σ of the history (solid) from ``BEFORE``
    samples before row ``row`` to ``after`` after, the branch ``rerun`` (dashed) where it runs, the
    true state, and the shown sample as a vertical line (its time twice on the x axis, the first a
    millionth of a sample earlier: uPlot ranges x only over rising values)."""
    first, last = max(0, row - BEFORE), min(len(history), row + max(after, 2))
    rows = np.insert(np.arange(first, last), row - first, row)          # the shown sample twice
    t_ms = (history.time_s[rows] - history.time_s[row]) * 1e3
    t_ms[row - first] -= 1e-6 * history.model.sample_time_s * 1e3     # x rising: the mark a hair before t = 0
    sigma = np.sqrt(history.P_post[rows, state, state])
    series = {"x̂⁺": history.x_post[rows, state], "+3σ": history.x_post[rows, state] + 3 * sigma,
              "−3σ": history.x_post[rows, state] - 3 * sigma, "true": history.truth[rows, state]}
    branch_values = np.full((3, len(rows)), np.nan)
    if rerun is not None:
        start = rerun.first_sample - history.first_sample                 # the branch's first row
        inside = (rows >= start) & (rows - start < len(rerun))
        kept = rows[inside] - start
        branch_sigma = np.sqrt(rerun.P_post[kept, state, state])
        branch_values[:, inside] = (rerun.x_post[kept, state], rerun.x_post[kept, state] + 3 * branch_sigma,
                                    rerun.x_post[kept, state] - 3 * branch_sigma)
    finite = np.concatenate([v[np.isfinite(v)] for v in (*series.values(), *branch_values)])
    low, high = float(finite.min()), float(finite.max())
    mark = np.full(len(rows), np.nan)
    mark[row - first], mark[row - first + 1] = low, high
    label, unit = history.model.states[state]
    factor, unit = prefixed(max(abs(low), abs(high)), unit)
    data = (t_ms, *(v / factor for v in (*series.values(), *branch_values, mark)))
    margin = 0.05 * (high - low) / factor or 1.0
    return data, {
        "title": f"{label}: the filter (solid), the branch (dashed), the shown sample",
        "axes": (viser.uplot.Axis(label="time from the shown sample [ms]"),
                 viser.uplot.Axis(label=f"{label} [{unit}]", size=70)),
        "scales": {"x": viser.uplot.Scale(time=False),
                   "y": viser.uplot.Scale(auto=False, min=low / factor - margin, max=high / factor + margin)}}


def kept_values(exercise, values: dict, model: FilterModel, q_scale: float, r_scale: float) -> dict | str:
    """The parameter values that make the branch's Q and R the running setting (every
    ``filter_q_*`` × ``q_scale``, ``filter_r_*`` × ``r_scale``), or why they cannot."""
    changed = {}
    for parameter in exercise.parameters:
        scale = {"filter_q_": q_scale, "filter_r_": r_scale}.get(parameter.name[:9])
        if scale is not None and scale != 1.0:
            try:
                changed[parameter.name] = parameter.parse(values[parameter.name] * scale)
            except ParameterError as error:
                return f"Not kept: {error}"
    if not changed:
        return "Not kept: this exercise has no filter_q_/filter_r_ controls to carry the branch's Q and R."
    tuned = model.scaled(q_scale, r_scale)
    trial = exercise.simulation({**values, **changed}).filter_tape()
    same = trial is not None and all(np.allclose(getattr(trial.model, name), getattr(tuned, name), rtol=1e-9,
                                                 atol=0.0) for name in ("Q", "R"))   # NaN (scheduled Q): never
    if not same:
        return ("Not kept: this exercise's controls cannot set exactly Q × and R × (its Q or R also depends on "
                "other settings); try the branch's factors on the controls by hand.")
    return changed


def keep(exercise, values: dict, model: FilterModel, q_scale: float, r_scale: float, follow) -> str:
    """Keep the branch through ``follow(exercise, changed values)`` (the tab's controls); what happened."""
    changed = kept_values(exercise, values, model, q_scale, r_scale)
    if isinstance(changed, str):
        return changed
    follow(exercise, changed)
    return ("Kept: " + ", ".join(f"{name} = {number(value)}" for name, value in changed.items())
            + " from now on (the controls show it; the filter's record starts again).")
