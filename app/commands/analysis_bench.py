"""``python -m app bench --analysis``: the CPU a tab's analyses cost, per exercise.

Measured the way a tab computes them (``lab_modules.evaluation.panel_analyses``, the pole map's and the
Analysis tab's views included), each exercise in a fresh process whose simulation kernels are
compiled (as in a running lab) but whose analyses are not yet remembered:

* first open: the Scope's results at the defaults, what a tab computes when it opens an exercise;
* slider move (Scope shown): the Scope's results after a move of the exercise's first numeric
  control (median of three moves: 5, 10 and 15 % up, or one step for an integer), and after a
  move of the first numeric control the Scope's analysis reads (the first may change nothing
  it shows: then its results are remembered);
* opening the Pole map or the Analysis tab after a move of that second control: that panel's
  results at the new values (its view built too: mode names, root locus, margins, chart data);
  for the Analysis tab also the CPU until its first result is drawn (an exercise that yields a
  quick result first shows it while the margins and the fuller results are computed).

Thread CPU time, so the figures hold on a shared machine (the wall time is not measured).
"""

from __future__ import annotations

import concurrent.futures
import json
import multiprocessing
import statistics
import time

from app.panels import plots, pole_map
from app.panels.readouts import grouped_markdown
from lab_modules.evaluation import poles
from lab_modules.evaluation.panel_analyses import margin_results, panel_results
from lab_modules.exercises import ANALYSIS, POLE_MAP, SCOPE, Analysis, Exercise, get, registry, results
from lab_modules.memo import ReadValues
from lab_modules.parameters import Parameter

MOVES = 3
SKIPPED = ("seed", "time_scale")                  # controls that change no analysis


def moved(exercise: Exercise, values: dict, parameter: Parameter, k: int) -> float:
    """The ``k``-th move of a numeric control from its default (5 % more per move, one step for an
    integer, a share of the range from 0), inside its range (``Exercise.parameter_ranges``)."""
    low, high = exercise.parameter_ranges(values).get(parameter.name, (parameter.minimum, parameter.maximum))
    if parameter.integer:
        up = parameter.default + 1
        return up if up <= high else parameter.default - 1
    default = float(parameter.default)
    value = default * (1 + 0.05 * (k + 1)) if default else low + 0.01 * (k + 1) * (high - low)
    return min(max(value, low), high)


def sliders(exercise: Exercise, values: dict) -> tuple[Parameter, Parameter]:
    """The exercise's first numeric control and the first one the Scope's analysis reads."""
    numeric = [p for p in exercise.parameters if not p.choices and p.name not in SKIPPED]
    read = ReadValues(values)
    for _ in results(exercise.analyse_panel(read, SCOPE)):
        pass
    return numeric[0], next((p for p in numeric if p.name in read.read), numeric[0])


def scope_job(exercise: Exercise, values: dict) -> Analysis:
    """The Scope's results and its readouts table; the last result."""
    last = None
    for last in panel_results(exercise, values, SCOPE):
        grouped_markdown(last.readouts, last.notes)
    return last


def pole_job(exercise: Exercise, values: dict, scope: Analysis) -> None:
    """The Pole map's results, their view (mode names, root locus) and the charts' data."""
    for result in panel_results(exercise, values, POLE_MAP) or (scope,):
        view = poles.view(exercise, values, result.poles)
        pole_map.charts(view)
        pole_map.table_markdown(view)


def analysis_job(exercise: Exercise, values: dict, scope: Analysis) -> float:
    """The Analysis tab in the order the tab shows it (``app.tab.analysis_view``): its first result
    (the margins still pending), then the margins, then every result with them; each time every
    chart's data.  Returns the CPU [ms] until the first result was drawn."""
    start = time.thread_time()
    found = panel_results(exercise, values, ANALYSIS) or (Analysis([], {}, [], scope.plots),)
    first_ms = None
    for result in found:
        if first_ms is None:
            draw_analysis(result, [("Margins", "computing …", "")], [], [])
            first_ms = 1e3 * (time.thread_time() - start)
        draw_analysis(result, *margin_results(exercise, values))
    return first_ms


def draw_analysis(result: Analysis, readouts: list, margin_plots: list, notes: list) -> None:
    """The Analysis tab's readouts table and chart data for one result with the margins' part."""
    grouped_markdown(result.readouts + readouts, result.notes + notes)
    for plot in result.plots + margin_plots:
        plots.plot_chart(plot)


def cpu_ms(job) -> tuple[float, object]:
    start = time.thread_time()
    result = job()
    return 1e3 * (time.thread_time() - start), result


def measure(name: str) -> dict:
    """The figures of one exercise (run in a process of its own)."""
    exercise = get(name)
    values = exercise.resolve({})
    exercise.simulation(values).advance(10)       # compiled kernels, as in a running lab
    first_open, _ = cpu_ms(lambda: scope_job(exercise, dict(values)))
    first, read = sliders(exercise, values)
    costs: dict[str, list[float]] = {"move": [], "move read": [], POLE_MAP: [], ANALYSIS: [], "first": []}
    for k in range(MOVES):
        at = {**values, first.name: moved(exercise, values, first, k)}
        costs["move"].append(cpu_ms(lambda at=at: scope_job(exercise, at))[0])
        at = {**values, read.name: moved(exercise, values, read, k + MOVES)}
        spent, scope = cpu_ms(lambda at=at: scope_job(exercise, at))
        costs["move read"].append(spent)
        costs[POLE_MAP].append(cpu_ms(lambda at=at, scope=scope: pole_job(exercise, at, scope))[0])
        spent, first_ms = cpu_ms(lambda at=at, scope=scope: analysis_job(exercise, at, scope))
        costs[ANALYSIS].append(spent)
        costs["first"].append(first_ms)
    median = {key: round(statistics.median(found), 1) for key, found in costs.items()}
    return {"exercise": name, "slider": first.name, "move_ms": median["move"], "slider_read": read.name,
            "move_read_ms": median["move read"], "open_pole_map_ms": median[POLE_MAP],
            "open_analysis_ms": median[ANALYSIS], "open_analysis_first_result_ms": median["first"],
            "first_open_ms": round(first_open, 1)}


def run(names: list[str]) -> list[dict]:
    """Each exercise in a fresh process, one after the other."""
    rows = []
    context = multiprocessing.get_context("spawn")
    for name in names:
        with concurrent.futures.ProcessPoolExecutor(max_workers=1, mp_context=context) as pool:
            rows.append(pool.submit(measure, name).result())
    return rows


def main(as_json: bool = False, only: list[str] | None = None) -> int:
    names = [get(name).name for name in only] if only else list(registry())
    if not as_json:
        print(f"{'exercise':18s} {'first control':26s} {'move':>6s}  {'first control read':26s} {'move':>6s} "
              f"{'open Pole map':>14s} {'open Analysis':>14s} {'its 1st result':>15s} {'first open':>11s}   "
              "(CPU ms; moves: Scope shown)",
              flush=True)
    rows = []
    for name in names:
        row, = run([name])
        rows.append(row)
        if not as_json:
            print(f"{name:18s} {row['slider']:26s} {row['move_ms']:6.1f}  {row['slider_read']:26s} "
                  f"{row['move_read_ms']:6.1f} {row['open_pole_map_ms']:14.1f} {row['open_analysis_ms']:14.1f} "
                  f"{row['open_analysis_first_result_ms']:15.1f} {row['first_open_ms']:11.1f}", flush=True)
    if as_json:
        print(json.dumps(rows, indent=2))
    return 0
