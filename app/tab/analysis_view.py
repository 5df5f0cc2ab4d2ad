"""A tab's analyses, computed for what the student looks at: the readouts under the scope after
every slider move; each other panel's part (the pole maps with mode names and root locus, the
Analysis tab's readouts, margins and plots, the worksheet's claims) only while that panel is
shown, and then for the values current at that moment.

Which panel tabs the browser shows, it tells through a beacon in each tab
(``app.infra.viser_internals.visibility_beacon``); a new tab shows the Scope.  One analysis
thread per tab works through the panels that are out of date, the Scope first; a slider move
supersedes what is under way (it stops at its next result), and hiding a panel stops its work.

Each panel's first result is shown at once (the readouts after a move, or the panel just
opened); fuller results take turns with the other tabs' (``app.tab.turns``), so one process's
analyses never crowd out its streaming.  Every result is remembered per setting of the
parameter values it read (``lab_modules.memo.Memo``), shared by the process's tabs: a
slider that an analysis never reads does not make it run again, and a class that opens an
exercise at its defaults computes each panel once (``lab_modules.evaluation.panel_analyses``).
"""

from __future__ import annotations

import itertools
import threading
import time
import traceback
from collections.abc import Callable, Iterator

from app.infra import viser_internals
from app.infra.traffic import callback
from app.panels import mode_picker, pole_map
from app.panels.plots import AnalysisPlots
from app.panels.readouts import grouped_markdown, pinned_markdown
from app.panels.text import readout_rows
from app.tab.state import LabState
from app.tab.turns import Turns
from app.tab.worker import TabWorker
from lab_modules.evaluation import margins, poles
from lab_modules.evaluation.panel_analyses import margin_results, panel_results, remembered_margins
from lab_modules.exercises import ANALYSIS, PANELS, POLE_MAP, SCOPE, Analysis, Exercise, results

#: The process's analyses take turns (app/tab/turns.py): one at a time shares the interpreter with streaming.
ANALYSIS_TURNS = Turns()
WORKSHEET, WORKSHEET_BESIDE = "Worksheet", "Worksheet beside"   # the worksheet's two places (app.panels.docks)
NOT_YET_SHOWN = "*Computed when this tab is shown …*"
KEY_ABSENT = "—"                                 # a key readout not computed yet
NO_PLOTS = "This exercise has no analysis plots."
POLE_MAP_NOTE = ("Poles in the s-plane (discrete poles mapped by s = ln z / T); the dashed line is "
                 "the imaginary axis, right of it is unstable. The first map leaves out the fast, "
                 "well-damped poles (sensor lag, amplifier) that squash the second.")


def analyses(exercise: Exercise, values: dict) -> Iterator[Analysis]:
    """The results of ``exercise.analyse(values)`` (everything), one by one."""
    return results(exercise.analyse(values))


class AnalysisView:
    """The analysis thread of one tab and what it shows (the views made anew for each exercise)."""

    def __init__(self, client, gui_lock, state: LabState, worker: TabWorker,
                 is_current: Callable[[int], bool]):
        """``is_current(generation)``: whether that generation still owns the tab's GUI (call
        holding ``gui_lock``)."""
        self.client, self.gui_lock, self.state, self.worker = client, gui_lock, state, worker
        self.is_current = is_current
        self.wakeup = threading.Condition()
        self.turn_wake = threading.Event()        # this tab's place in line for an analysis turn
        self.thread: threading.Thread | None = None
        self.shown = {SCOPE}                      # panels the browser shows (kept across exercises)
        self.serials = itertools.count(1)
        self.target: tuple | None = None          # (generation, exercise, values, serial): the newest values
        self.done: dict[str, int] = {}            # panel -> serial of the values it shows
        self.scope_last: tuple[int, Analysis | None] = (0, None)   # the Scope's last result and its serial
        self.handoff: tuple | None = None         # (values, results, first): the Scope's, begun by ``first``
        self.on_worksheet: Callable[[], None] = lambda: None   # the worksheet's claims, once it is shown
        self.on = None                            # the tab's GUI callback factory (``TabWorker.on``)
        self.shown_analysis: Analysis | None = None   # the Scope's, redrawn with fresh scope readouts
        self.readouts = None
        self.pinned = None                        # the key readouts, above the scope's charts
        self.panel_shown: tuple[int, Analysis | None] = (0, None)   # the Analysis tab's (serial, result)
        self.panel_readouts = None
        self.plots: AnalysisPlots | None = None
        self.pole_tab = None
        self.pole_status = None
        self.pole_table = None
        self.shown_poles: poles.PoleView | None = None
        self.mode_picker: mode_picker.ModePicker | None = None

    # -- what a new exercise shows first (on the worker, holding the GUI lock) ------------------
    def first(self, exercise: Exercise, values: dict) -> Analysis:
        """The Scope's quick first result: what the new exercise's readouts open on (its analysis
        thread goes on from there)."""
        self.done, self.scope_last, self.panel_shown = {}, (0, None), (0, None)
        self.shown_analysis = self.shown_poles = self.mode_picker = None
        found = panel_results(exercise, dict(values), SCOPE)
        first = next(found)
        self.handoff = (dict(values), found, first)
        return first

    def add_pinned(self, gui) -> None:
        """The key readouts of the worksheet's tasks, above the charts (in view at 1366 x 768); and
        the Scope tab's beacon: its charts stream only while it is shown (``scope_shown``)."""
        self.add_beacon(gui, SCOPE)
        self.pinned = gui.add_markdown("")

    def scope_shown(self) -> bool:
        """Whether the browser shows the Scope tab (so far as its beacon said; a new tab does)."""
        return SCOPE in self.shown

    def add_readouts(self, gui, first: Analysis) -> None:
        self.shown_analysis = first
        self.readouts = gui.add_markdown("")
        self._show_readouts(first)

    def add_beacon(self, gui, panel: str) -> None:
        """The browser says when this panel tab is shown or hidden (its analyses are computed then);
        recorded at once on the event loop, not behind the tab's other events."""
        viser_internals.visibility_beacon(gui, panel, callback(lambda _: self.set_shown(panel, True)),
                                          callback(lambda _: self.set_shown(panel, False)))

    def add_worksheet_beacons(self, gui, tabs: dict) -> None:
        """Beacons in the worksheet's tab and in its place beside the panels (if docked there)."""
        for place, name in (("Worksheet", WORKSHEET), ("beside", WORKSHEET_BESIDE)):
            if place in tabs:
                with tabs[place]:
                    self.add_beacon(gui, name)

    def add_pole_map(self, gui, tab, on) -> None:
        """The Pole map tab: its maps, mode picker, legend and table come with its first view."""
        self.add_beacon(gui, POLE_MAP)
        self.pole_tab, self.on = tab, on
        self.pole_status = gui.add_markdown(NOT_YET_SHOWN)

    def add_analysis_tab(self, gui, tab) -> None:
        """The Analysis tab: its readouts (the margins among them), then its plots."""
        self.add_beacon(gui, ANALYSIS)
        self.panel_readouts = gui.add_markdown(NOT_YET_SHOWN)
        self.plots = AnalysisPlots(gui, tab, self.client.atomic, [])

    def _pick_mode(self) -> None:
        with self.gui_lock, self.client.atomic():
            if self.mode_picker is not None:
                self.mode_picker.pick(self.mode_picker.dropdown.value)

    # -- what the browser shows (on the event loop: quick) -----------------------------------
    def set_shown(self, panel: str, shown: bool) -> None:
        """The browser shows (or hides) ``panel``: a panel out of date is analysed now."""
        with self.wakeup:
            if shown:
                self.shown.add(panel)
            else:
                self.shown.discard(panel)
            self.wakeup.notify()
        self.turn_wake.set()                      # work for a panel now hidden is moot
        if shown and panel in (WORKSHEET, WORKSHEET_BESIDE):
            self.worker.post("worksheet shown", self.on_worksheet)

    # -- the analysis thread ---------------------------------------------------------------
    def ask(self, generation: int, exercise: Exercise, values: dict) -> None:
        """Analyse ``values``; a newer request supersedes an older one."""
        with self.wakeup:
            self.target = (generation, exercise, values, next(self.serials))
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

    def _next_job(self) -> tuple[str, tuple] | None:
        """The first panel (Scope first) that is shown and out of date, with the values it needs."""
        if self.target is None:
            return None
        for panel in PANELS:
            if (panel == SCOPE or panel in self.shown) and self.done.get(panel) != self.target[3]:
                return panel, self.target
        return None

    def _moot(self, panel: str, serial: int) -> bool:
        """Whether work for ``panel`` at ``serial`` is no longer wanted."""
        return (self.worker.closed or self.target[3] != serial
                or (panel != SCOPE and panel not in self.shown))

    def _work(self) -> None:
        """One panel at a time, always for the newest values."""
        while True:
            with self.wakeup:
                while (job := self._next_job()) is None and not self.worker.closed:
                    self.wakeup.wait()
                if self.worker.closed:
                    return
            panel, (generation, exercise, values, serial) = job
            try:
                self._run(panel, self._steps(panel, generation, exercise, values, serial), serial)
            except (ValueError, ArithmeticError) as error:   # incl. ParameterError, LinAlgError: the tab's
                traceback.print_exc()                         # analyses go on at the next slider move
                self._failed(panel, generation, serial, error)

    def _run(self, panel: str, steps: Iterator[None], serial: int) -> None:
        """Each ``next(steps)`` computes and shows one result: the first at once, the others in turns."""
        spent = time.thread_time()
        more = next(steps, False) is not False
        while more and not self._moot(panel, serial):
            self.worker.pace(time.thread_time() - spent, self.wakeup)
            spent = time.thread_time()
            with ANALYSIS_TURNS.turn(self.turn_wake, abandon=lambda: self._moot(panel, serial)) as held:
                more = held and next(steps, False) is not False
        self.worker.pace(time.thread_time() - spent, self.wakeup)

    def _steps(self, panel: str, generation: int, exercise: Exercise, values: dict, serial: int) -> Iterator[None]:
        if panel == SCOPE:
            return self._scope_steps(generation, exercise, values, serial)
        if panel == POLE_MAP:
            return self._pole_steps(generation, exercise, values, serial)
        return self._analysis_steps(generation, exercise, values, serial)

    def _finished(self, panel: str, generation: int, serial: int) -> None:
        with self.gui_lock:
            if self.is_current(generation):
                self.done[panel] = serial

    def _failed(self, panel: str, generation: int, serial: int, error: Exception) -> None:
        """The panel says so until an analysis succeeds (and is not retried at these values)."""
        message = f"⚠️ The analysis failed at these settings: {error}"
        with self.gui_lock:
            if not self.is_current(generation):
                return
            self.done[panel] = serial
            if panel == SCOPE:
                self.shown_analysis = None
                self.readouts.content = message
                self.pinned.content = ""
            elif panel == ANALYSIS:
                self.panel_shown = (0, None)
                self.panel_readouts.content = message
            elif self.mode_picker is None:
                self.pole_status.content = message
            else:
                self.pole_table.content = message

    def _showing(self, generation: int, serial: int) -> bool:
        """Whether a result for ``serial`` may still be shown (call holding ``gui_lock``)."""
        return self.is_current(generation) and self.target[3] == serial

    # -- the Scope: readouts after every move --------------------------------------------
    def _scope_steps(self, generation: int, exercise: Exercise, values: dict, serial: int) -> Iterator[None]:
        handoff, self.handoff = self.handoff, None
        if handoff is not None and handoff[0] == values:
            found = itertools.chain((handoff[2],), handoff[1])
        else:
            found = panel_results(exercise, values, SCOPE)
        last = None
        for last in found:
            with self.gui_lock:
                if not self._showing(generation, serial):
                    return
                self.shown_analysis = last
                self._show_readouts(last)
                self.client.flush()                   # the readouts go out now, not with the next window
            yield
        with self.gui_lock:
            if self.is_current(generation):
                self.scope_last = (serial, last)
        self._finished(SCOPE, generation, serial)

    def _from_scope(self, serial: int) -> Iterator[Analysis]:
        """The Scope's last result at ``serial``, for a panel that shows its part of it."""
        done, last = self.scope_last
        return iter((last,) if done == serial and last is not None else ())

    # -- the Pole map ----------------------------------------------------------------------
    def _pole_steps(self, generation: int, exercise: Exercise, values: dict, serial: int) -> Iterator[None]:
        for result in panel_results(exercise, values, POLE_MAP) or self._from_scope(serial):
            view = poles.view(exercise, values, result.poles)   # mode names and root locus: cached per setting
            with self.gui_lock:
                if not self._showing(generation, serial):
                    return
                self._draw_poles(view)
            yield
        self._finished(POLE_MAP, generation, serial)

    def _draw_poles(self, view: poles.PoleView) -> None:
        """Both maps, the picker and the table (made with the first view; call holding ``gui_lock``)."""
        gui = self.client.gui
        if self.mode_picker is None:
            with self.client.atomic(), self.pole_tab:
                # Hidden, not removed: a browser may apply the note's first update after a removal
                # that follows it closely, and then reports an update of a missing element.
                self.pole_status.visible = False
                plots = tuple(gui.add_uplot(data, **options, aspect=1.6) for data, options in pole_map.charts(view))
                self.mode_picker = mode_picker.ModePicker(gui, plots, view)
                self.mode_picker.dropdown.on_update(self.on("show mode", self._pick_mode))
                gui.add_markdown(pole_map.legend_markdown())
                gui.add_markdown(POLE_MAP_NOTE)
                self.pole_table = gui.add_markdown(pole_map.table_markdown(view))
        elif not view.same_as(self.shown_poles):
            with self.client.atomic():                # series, axes and data change together
                self.mode_picker.draw(view)
                self.pole_table.content = pole_map.table_markdown(view)
        self.shown_poles = view

    # -- the Analysis tab: its readouts, the margins and the plots --------------------------
    def _analysis_steps(self, generation: int, exercise: Exercise, values: dict, serial: int) -> Iterator[None]:
        found = panel_results(exercise, values, ANALYSIS)
        if found is None:                             # the plots of the Scope's result
            found = (Analysis([], {}, [], result.plots) for result in self._from_scope(serial))
        loops = remembered_margins(exercise, values)
        for result in found:
            if not self._show_panel(generation, serial, result, loops):
                return
            yield
            if loops is None:                         # the margins take longer: shown next
                loops = margin_results(exercise, values)
                if not self._show_panel(generation, serial, result, loops):
                    return
                yield
        self._finished(ANALYSIS, generation, serial)

    def _show_panel(self, generation: int, serial: int, result: Analysis, loops: tuple | None) -> bool:
        """The Analysis tab's readouts and plots, with the margins (``loops``; None: not yet)."""
        readouts, plots, notes = loops if loops is not None else ([("Margins", "computing …", "")], [], [])
        shown = margins.with_margins(result, margins.MarginView(readouts, plots, notes))
        if loops is not None and not shown.plots:
            shown.notes.append(NO_PLOTS)
        with self.gui_lock:
            if not self._showing(generation, serial):
                return False
            self.panel_shown = (serial, shown)
            self.panel_readouts.content = grouped_markdown(shown.readouts, shown.notes)
            if self.shown_analysis is not None:       # its key readouts pinned above the scope too
                self._show_readouts(self.shown_analysis)
            self.plots.update(shown.plots)
            self.client.flush()
        return True

    # -- readouts ------------------------------------------------------------------------
    def readout_rows(self, result: Analysis | None) -> list[tuple[str, object, str]]:
        """The analysis's figures, then the exercise's figures of the scope window."""
        return readout_rows(result, self.state.exercise, self.state.trace())

    def export_rows(self) -> list[tuple[str, object, str]]:
        """The readouts for a report: the Scope's with the scope window's, then the Analysis tab's
        if they belong to the current values."""
        return self.readout_rows(self.shown_analysis) + self._analysis_tab_rows()

    def _analysis_tab_rows(self) -> list[tuple[str, object, str]]:
        """The Analysis tab's readouts if they belong to the current values, else none."""
        serial, shown = self.panel_shown
        current = shown is not None and self.target is not None and serial == self.target[3]
        return list(shown.readouts) if current else []

    def _show_readouts(self, result: Analysis) -> None:
        """The key readouts above the charts and every readout below them (call holding ``gui_lock``);
        unchanged texts are not sent again (exercises without scope readouts send nothing each second).
        A key readout of the Analysis tab (a sweep: rotor_at_speed's critical speeds, kalman_noise's
        largest gain factors) is not computed with every slider move: it is pinned once that tab has
        computed it for the current values, a dash until then."""
        rows = self.readout_rows(result)
        keys = self.state.exercise.key_readouts
        for handle, text in ((self.pinned, pinned_markdown(rows + self._analysis_tab_rows(), keys, KEY_ABSENT)),
                             (self.readouts, grouped_markdown(rows, result.notes))):
            if handle is not None and handle.content != text:
                handle.content = text

    def refresh_live_readouts(self) -> None:
        """Redraw the readouts with the scope window's current figures (call holding ``gui_lock``)."""
        if self.shown_analysis is not None:
            self._show_readouts(self.shown_analysis)
