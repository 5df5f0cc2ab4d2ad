"""What each panel of a tab computes, remembered for all tabs of the process: the results of
``Exercise.analyse_panel`` and the margins of ``Exercise.open_loops``, each per exercise, panel
and setting of the parameter values it read (``lab_modules.memo.Memo``).  A class that
opens an exercise at its defaults computes each panel once; a slider an analysis never reads
does not make it run again."""

from __future__ import annotations

from collections.abc import Iterator

from lab_modules.evaluation import margins
from lab_modules.exercises import Analysis, Exercise, results
from lab_modules.memo import Memo, ReadValues

PANEL_RESULTS = Memo(size=256)
MARGIN_RESULTS = Memo(size=128)


def panel_results(exercise: Exercise, values: dict, panel: str) -> Iterator[Analysis] | None:
    """The results of ``exercise.analyse_panel(values, panel)`` one by one, or None (the panel shows
    its part of the Scope's result).  A remembered setting gives its last result at once."""
    key = (exercise.name, panel)
    found = PANEL_RESULTS.find(key, values)
    if found is not None:
        return iter((found[0],))
    read = ReadValues(values)
    part = exercise.analyse_panel(read, panel)
    return None if part is None else _remembered(key, values, read, results(part))


def _remembered(key, values: dict, read: ReadValues, found: Iterator[Analysis]) -> Iterator[Analysis]:
    last = None
    for last in found:
        yield last
    if last is not None:                          # computed to the end (not superseded)
        PANEL_RESULTS.keep(key, values, read.read, last)


def margin_results(exercise: Exercise, values: dict) -> margins.MarginView:
    """The readouts, plots and notes of the exercise's open loops (``lab_modules.evaluation.margins``)."""
    return MARGIN_RESULTS.call((exercise.name,), values, lambda read: margins.margin_view(exercise, read))


def remembered_margins(exercise: Exercise, values: dict) -> margins.MarginView | None:
    """The margins if they are remembered for ``values`` (None: computing them takes a while)."""
    found = MARGIN_RESULTS.find((exercise.name,), values)
    return None if found is None else found[0]
