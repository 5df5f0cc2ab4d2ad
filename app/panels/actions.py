"""Exercise actions (``Exercise.actions``): buttons that run a longer computation on
demand, e.g. a Monte-Carlo run, on a thread of their own.

The tab stays live meanwhile (the simulation, the scope and the sliders go on).
Each result the action yields (progress first, the final result last) replaces
the table, notes and plots below its button.  A second press starts the action
afresh and the older run stops at its next yield; so does a run whose exercise
was switched away or whose tab closed.  The run's CPU time is booked on the
tab's ``CpuBudget``, like its analyses.
"""

from __future__ import annotations

import threading
import time
import traceback
from collections.abc import Callable, Iterator

from lab_modules.exercises import Action, Analysis, Plot
from lab_modules.formatting import number

PLOT_ASPECT = 1.6                 # result plots in the 380 px control panel
RESULT_DIGITS = 4                 # one more than a readout: a Monte-Carlo ratio of 1.004 is not 1


def _steps(result: Analysis | Iterator[Analysis]) -> Iterator[Analysis]:
    return iter((result,)) if isinstance(result, Analysis) else result


def result_markdown(result: Analysis, running: bool) -> str:
    """An action's readouts as a table, then its notes (the first one in bold while it runs)."""
    lines = []
    if result.readouts:
        lines += ["| quantity | value | unit |", "|---|---:|---|"]
        lines += [f"| {label} | {number(value, RESULT_DIGITS)} | {unit} |"
                  for label, value, unit in result.readouts]
    notes = list(result.notes)
    if running and notes:
        notes[0] = f"⏳ **{notes[0]}**"
    return "\n".join(lines) + ("\n\n" if lines else "") + "\n\n".join(f"*{n}*" if i or not running else n
                                                                       for i, n in enumerate(notes))


class ActionPanel:
    """The buttons of one exercise's actions in one tab (one generation of it)."""

    def __init__(self, gui, exercise, on, values: Callable[[], dict], is_current: Callable[[], bool], gui_lock,
                 pacer, client, plot_chart: Callable[[Plot], tuple[tuple, dict]]):
        """Add a button and a result text per action to the current container (the controls).
        ``on(key, action)`` makes a GUI callback that runs ``action`` on the tab's worker;
        ``values()`` the tab's current values; ``is_current()`` whether this exercise still owns
        the tab; ``pacer.pace(cpu_s)`` books CPU time on the tab's budget; ``client`` sends
        (``flush``) and names threads; ``plot_chart`` turns a ``Plot`` into uPlot arguments."""
        self.gui, self.exercise, self.values, self.is_current = gui, exercise, values, is_current
        self.gui_lock, self.pacer, self.client, self.plot_chart = gui_lock, pacer, client, plot_chart
        self.runs: dict[str, int] = {}                  # action label -> number of its newest run
        self.results: dict[str, object] = {}            # action label -> its result text
        self.plots: dict[str, list] = {}                # action label -> its result plots (added lazily)
        for action in self.exercise.actions:
            button = gui.add_button(action.label, hint=action.hint or None)
            self.results[action.label] = gui.add_markdown("")
            self.plots[action.label] = []
            button.on_click(on(("action", action.label), lambda a=action: self.start(a)))

    def start(self, action: Action) -> None:
        """Run ``action`` on a thread of its own at the tab's current values (newest press wins)."""
        run = self.runs.get(action.label, 0) + 1
        self.runs[action.label] = run
        values = self.values()
        self.results[action.label].content = "⏳ **starting …**"
        threading.Thread(target=self._run, args=(action, values, run), daemon=True,
                         name=f"action-{self.client.client_id}").start()

    def _current(self, action: Action, run: int) -> bool:
        return self.runs.get(action.label) == run and self.is_current()

    def _run(self, action: Action, values: dict, run: int) -> None:
        spent = time.thread_time()
        steps = _steps(getattr(self.exercise, action.method)(values))
        try:
            result = next(steps, None)
            while result is not None:
                following = next(steps, None)           # one step ahead: the last result is the final one
                with self.gui_lock:
                    if not self._current(action, run):
                        return
                    self._show(action, result, running=following is not None)
                result = following
                self.pacer.pace(time.thread_time() - spent)
                spent = time.thread_time()
                if not self._current(action, run):
                    return
        except Exception as error:  # noqa: BLE001 - shown below the button; the tab goes on
            traceback.print_exc()
            with self.gui_lock:
                if self._current(action, run):
                    self.results[action.label].content = f"⚠️ {action.label} failed: {error}"
        finally:
            close = getattr(steps, "close", None)      # a superseded generator stops here
            if close is not None:
                close()

    def _show(self, action: Action, result: Analysis, running: bool) -> None:
        """Show one result (call holding ``gui_lock``): its text, and its plots below it."""
        text = self.results[action.label]
        text.content = result_markdown(result, running)
        handles = self.plots[action.label]
        for index, plot in enumerate(result.plots):
            data, options = self.plot_chart(plot)
            if index < len(handles):
                handles[index].data, handles[index].scales = data, options["scales"]
                handles[index].title = options["title"]
            else:                                       # right below the text (same container: the root)
                handles.append(self.gui.add_uplot(data, **options, aspect=PLOT_ASPECT,
                                                  order=text.order + 0.001 * (index + 1)))
        self.client.flush()
