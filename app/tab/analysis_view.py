"""A tab's analysis: the readouts under the scope, the Pole map tab and the Analysis tab's
plots, computed on the tab's analysis thread for the newest values.

A slider move asks for an analysis; a newer request supersedes an older one, which stops
at its next intermediate result.  The quick first result (the readouts) is shown at once;
the fuller ones take turns with the other tabs' (``app.tab.turns``), so one process's
analyses never crowd out its streaming.
"""

from __future__ import annotations

import threading
import time
import traceback
from collections.abc import Callable, Iterator

from app.panels import mode_picker, pole_map
from app.panels.plots import AnalysisPlots
from app.panels.readouts import grouped_markdown, pinned_markdown
from app.panels.text import readout_rows
from app.tab.state import LabState
from app.tab.turns import Turns
from app.tab.worker import TabWorker
from lab_modules.evaluation import margins, poles
from lab_modules.exercises import Analysis, Exercise

#: The process's analyses take turns (app/tab/turns.py): one at a time shares the interpreter with streaming.
ANALYSIS_TURNS = Turns()
POLE_MAP_NOTE = ("Poles in the s-plane (discrete poles mapped by s = ln z / T); the dashed line is "
                 "the imaginary axis, right of it is unstable. The first map leaves out the fast, "
                 "well-damped poles (sensor lag, amplifier) that squash the second.")


def analyses(exercise: Exercise, values: dict) -> Iterator[Analysis]:
    """The results of ``exercise.analyse(values)``, computed as they are asked for: ``analyse``
    returns one ``Analysis`` or yields a quick one, then fuller ones."""
    result = exercise.analyse(values)
    if isinstance(result, Analysis):
        yield result
    else:
        yield from result


class AnalysisView:
    """The analysis thread of one tab and what it shows (made anew for each exercise by ``add_*``)."""

    def __init__(self, client, gui_lock, state: LabState, worker: TabWorker,
                 is_current: Callable[[int], bool]):
        """``is_current(generation)``: whether that generation still owns the tab's GUI (call
        holding ``gui_lock``)."""
        self.client, self.gui_lock, self.state, self.worker = client, gui_lock, state, worker
        self.is_current = is_current
        self.request: tuple[int, Exercise, dict] | None = None
        self.wakeup = threading.Condition()
        self.turn_wake = threading.Event()        # this tab's place in line for an analysis turn
        self.thread: threading.Thread | None = None
        self.shown_analysis: Analysis | None = None   # the last shown, redrawn with fresh scope readouts
        self.shown_margins = margins.MarginView([], [], [])
        self.shown_poles: poles.PoleView | None = None
        self.readouts = None
        self.pinned = None                        # the key readouts, above the scope's charts
        self.plots: AnalysisPlots | None = None
        self.pole_table = None
        self.mode_picker: mode_picker.ModePicker | None = None

    # -- what a new exercise shows first (on the worker, holding the GUI lock) ------------------
    def first(self, exercise: Exercise, values: dict) -> Analysis:
        """The quick first result with the margins: what the new exercise's views open on."""
        self.shown_analysis, self.shown_poles = None, None
        first = next(analyses(exercise, dict(values)))
        self.shown_margins = margins.margin_view(exercise, dict(values))
        return margins.with_margins(first, self.shown_margins)

    def add_pinned(self, gui) -> None:
        """The key readouts of the worksheet's tasks, above the charts (in view at 1366 x 768)."""
        self.pinned = gui.add_markdown("")

    def add_readouts(self, gui) -> None:
        self.readouts = gui.add_markdown("*computing …*")

    def add_pole_map(self, gui, exercise: Exercise, values: dict, first: Analysis, on) -> None:
        """The Pole map tab: both maps, the mode picker, the legend and the table."""
        self.shown_poles = poles.view(exercise, dict(values), first.poles)
        plots = tuple(gui.add_uplot(data, **options, aspect=1.6)
                      for data, options in pole_map.charts(self.shown_poles))
        self.mode_picker = mode_picker.ModePicker(gui, plots, self.shown_poles)
        self.mode_picker.dropdown.on_update(on("show mode", self._pick_mode))
        gui.add_markdown(pole_map.legend_markdown())
        gui.add_markdown(POLE_MAP_NOTE)
        self.pole_table = gui.add_markdown(pole_map.table_markdown(self.shown_poles))

    def add_plots(self, gui, container, first: Analysis) -> None:
        self.plots = AnalysisPlots(gui, container, self.client.atomic, first.plots)

    def _pick_mode(self) -> None:
        with self.gui_lock, self.client.atomic():
            self.mode_picker.pick(self.mode_picker.dropdown.value)

    # -- the analysis thread ---------------------------------------------------------------
    def ask(self, generation: int, exercise: Exercise, values: dict) -> None:
        """Analyse ``values``; a newer request supersedes an older one."""
        with self.wakeup:
            self.request = (generation, exercise, values)
            self.wakeup.notify()
        self.turn_wake.set()                      # an analysis waiting for its turn is moot now
        if self.thread is None:
            self.thread = threading.Thread(target=self._work, name=f"analysis-{self.client.client_id}",
                                           daemon=True)
            self.thread.start()

    def close(self) -> None:
        with self.wakeup:
            self.wakeup.notify()
        self.turn_wake.set()

    def _superseded(self) -> bool:
        return self.request is not None or self.worker.closed

    def _work(self) -> None:
        """One analysis at a time per tab, always of the newest values: an analysis
        whose values were superseded stops at its next intermediate result."""
        while True:
            with self.wakeup:
                while self.request is None and not self.worker.closed:
                    self.wakeup.wait()
                if self.worker.closed:
                    return
                (generation, exercise, values), self.request = self.request, None
            spent = time.thread_time()
            try:
                results, last, more = analyses(exercise, values), None, True
                while more:
                    if last is None:                      # the quick first result (the readouts) at once
                        last, more = self._show_next(generation, exercise, values, results, last)
                    else:                                 # the fuller ones take turns
                        with ANALYSIS_TURNS.turn(self.turn_wake, abandon=self._superseded) as held:
                            last, more = (self._show_next(generation, exercise, values, results, last)
                                          if held else (last, False))
                    self.worker.pace(time.thread_time() - spent, self.wakeup)
                    spent = time.thread_time()
            except (ValueError, ArithmeticError) as error:   # incl. ParameterError, LinAlgError: the tab's
                traceback.print_exc()                         # analyses go on at the next slider move
                with self.gui_lock:
                    if self.is_current(generation):
                        self.shown_analysis = None        # the message stays until an analysis succeeds
                        self.readouts.content = f"⚠️ The analysis failed at these settings: {error}"

    def _show_next(self, generation: int, exercise: Exercise, values: dict, results: Iterator[Analysis],
                   last: Analysis | None) -> tuple[Analysis | None, bool]:
        """Show the analysis's next result, or after its last one the last with fresh margins;
        returns the newest result shown and whether to go on."""
        result = next(results, None)
        if result is None:                            # ... the new margins are ready (they take longer)
            if last is not None and self.request is None:
                fresh = margins.margin_view(exercise, values)
                with self.gui_lock:
                    if self.is_current(generation):
                        self.shown_margins = fresh
                self._show(generation, margins.with_margins(last, fresh))
            return last, False
        shown = margins.with_margins(result, self.shown_margins)   # the last margins until ...
        if self.request is not None or not self._show(generation, shown):
            return last, False
        return result, True

    def _show(self, generation: int, result: Analysis) -> bool:
        """Show an analysis; False if the tab no longer shows its exercise."""
        with self.gui_lock:
            if not self.is_current(generation):
                return False
            self.shown_analysis = result
            self._show_readouts(result)
            self.client.flush()                       # the readouts go out now, not with the next window
            self.plots.update(result.plots)
            exercise, values = self.state.exercise, self.state.values_now()
        pole_view = poles.view(exercise, values, result.poles)   # the root locus: cached per setting
        with self.gui_lock:
            if not self.is_current(generation):
                return False
            if not pole_view.same_as(self.shown_poles):
                self.shown_poles = pole_view
                with self.client.atomic():            # series, axes and data change together
                    self.mode_picker.draw(pole_view)
                    self.pole_table.content = pole_map.table_markdown(pole_view)
        return True

    # -- readouts ------------------------------------------------------------------------
    def readout_rows(self, result: Analysis | None) -> list[tuple[str, object, str]]:
        """The analysis's figures, then the exercise's figures of the scope window."""
        return readout_rows(result, self.state.exercise, self.state.trace())

    def _show_readouts(self, result: Analysis) -> None:
        """The key readouts above the charts and every readout below them (call holding ``gui_lock``);
        unchanged texts are not sent again (exercises without scope readouts send nothing each second)."""
        rows = self.readout_rows(result)
        for handle, text in ((self.pinned, pinned_markdown(rows, self.state.exercise.key_readouts)),
                             (self.readouts, grouped_markdown(rows, result.notes))):
            if handle is not None and handle.content != text:
                handle.content = text

    def refresh_live_readouts(self) -> None:
        """Redraw the readouts with the scope window's current figures (call holding ``gui_lock``)."""
        if self.shown_analysis is not None:
            self._show_readouts(self.shown_analysis)
