"""A tab as a student's assignment: opened from the link (``?assignment=CODE``), the student's name
or id asked once (kept in the browser), then the assignment's exercise on the student's own
variant with the fixed controls disabled, and a Submit button.

A submission is the tab's current settings of the parameters the student may change; it is graded
on the server (``coursework.submit``: the metrics recomputed headless on the student's variant)
on the tab's worker, whose CPU budget it is charged to like any event: a student pressing Submit
again and again delays only their own tab.  Unknown assignment codes count as codes that open
nothing (``access.Throttle``), as in the "Saved experiment" folder."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

from app.infra import coursework
from app.infra.access import TAB_CODE_TRIES_BURST, TAB_CODE_TRIES_PER_MINUTE, Throttle
from app.infra.store import Store, StoreError
from app.panels.assignment import JoinDialog, SubmitPanel, fix_controls, results_markdown
from app.panels.text import escaped
from app.tab.state import LabState
from app.tab.worker import TabWorker
from lab_modules.evaluation import assignments
from lab_modules.evaluation.assignments import Assignment
from lab_modules.exercises import get
from lab_modules.parameters import ParameterError

BROWSER_KEY = "assignment_student"   # the browser keeps the id its student gave (asked once)
BROWSER_WAIT_S = 1.0


def plain(value):
    """A setting as JSON keeps it (numpy scalars as Python numbers)."""
    return value.item() if hasattr(value, "item") else value


class AssignmentTab:
    """The assignment a tab is given to (None until the student joined one)."""

    def __init__(self, store: Store | None, client, gui_lock, worker: TabWorker, state: LabState,
                 switch: Callable[[object, dict], None], code_tries: Throttle | None = None,
                 address: str = "unknown"):
        """``switch(exercise, overrides)`` shows the assignment's exercise at ``overrides`` (on the worker)."""
        self.store, self.client, self.gui_lock, self.worker, self.state = store, client, gui_lock, worker, state
        self.switch = switch
        self.code_tries, self.address = code_tries, address
        self.tab_code_tries = Throttle("assignment codes", TAB_CODE_TRIES_BURST, TAB_CODE_TRIES_PER_MINUTE, log=False)
        self.code: str | None = None
        self.assignment: Assignment | None = None
        self.student: str | None = None
        self.dialog: JoinDialog | None = None
        self.panel: SubmitPanel | None = None

    @property
    def active(self) -> bool:
        return self.student is not None

    # -- joining ------------------------------------------------------------------------
    def offer(self, typed_code: str, warn: Callable[[str], None]) -> None:
        """The page's link names an assignment: ask the student's id (``warn``: a line in the tab)."""
        if self.store is None:
            warn("⚠️ This lab keeps no assignments (it runs without a store).")
            return
        throttles = [(self.tab_code_tries, "tab")] + ([(self.code_tries, self.address)] if self.code_tries else [])
        wait_s = max(throttle.wait_s(key) for throttle, key in throttles)
        if wait_s > 0:
            warn(f"⚠️ Too many codes that open nothing: try the link again in {math.ceil(wait_s)} s.")
            return
        try:
            code, assignment = coursework.load(self.store, typed_code)
        except StoreError as error:
            for throttle, key in throttles:
                throttle.failed(key)
            warn(f"⚠️ The link's assignment did not open: {escaped(error)}")
            return
        try:
            remembered = self.client.local_storage.get_item(BROWSER_KEY, timeout=BROWSER_WAIT_S) or ""
        except (RuntimeError, TimeoutError):
            remembered = ""
        self.worker.check_open()
        with self.gui_lock:
            if self.dialog is not None:
                self.dialog.close()
            self.dialog = JoinDialog(self.client.gui, assignment, code, remembered,
                                     lambda student: self.join(code, assignment, student), self.worker.on)

    def join(self, code: str, assignment: Assignment, typed: str) -> None:
        """The student gave their id: their variant (and their last submission's settings) in this tab."""
        try:
            student = assignments.check_student(typed)
            self.store.join(code, student)
            submitted = self.store.submissions(code, student)
        except (ParameterError, StoreError) as error:
            self.dialog.message.content = f"⚠️ {escaped(error)}"
            return
        self.client.local_storage.set_item(BROWSER_KEY, student)
        self.code, self.assignment, self.student = code, assignment, student
        self.dialog.close()
        self.dialog = None
        last = submitted[-1].parameters if submitted else {}
        self.switch(get(assignment.exercise),
                    {**assignment.base, **last, **assignments.variant(assignment, code, student)})

    # -- the assignment's tab -------------------------------------------------------------
    def add_panel(self, gui, exercise) -> None:
        """The "Assignment" folder, when ``exercise`` is the assignment's (call while the GUI is built);
        another exercise opened in the tab (a saved experiment) leaves the assignment."""
        self.panel = None
        if not self.active:
            return
        if exercise.name != self.assignment.exercise:
            self.code = self.assignment = self.student = None
            return
        self.panel = SubmitPanel(gui, self.assignment, self.code, self.student, self.submit, self.worker.on)
        handed_in = self.store.submissions(self.code, self.student)
        if handed_in:
            self.show(handed_in[-1].results, handed_in[-1].score, handed_in)

    def fix(self, inputs: dict, entries: dict, chooser) -> None:
        """Disable the fixed controls (after they were built)."""
        if self.panel is not None:
            fix_controls(inputs, entries, self.assignment, chooser)

    def submit(self) -> None:
        """Grade the tab's current settings on the student's variant (on the worker, charged to the tab)."""
        if self.panel is None:
            return
        values = self.state.values_now()
        settings = {name: plain(values[name]) for name in assignments.changeable(self.assignment)
                    if name in values}
        self.panel.results.content = "*Grading on the server …*"
        self.client.flush()
        started = time.perf_counter()
        try:
            submission, _ = coursework.submit(self.store, self.code, self.assignment, self.student, settings)
        except (ParameterError, StoreError) as error:
            self.panel.results.content = f"⚠️ Not graded: {escaped(error)}"
            return
        self.show(submission.results, submission.score, self.store.submissions(self.code, self.student),
                  time.perf_counter() - started)

    def show(self, results: list, score: float, handed_in: list, took_s: float | None = None) -> None:
        """The results of the newest submission beside the Submit button, and the score that counts."""
        counted = assignments.counted_score(self.assignment, [s.score for s in handed_in])
        timing = f" (graded in {took_s:.1f} s)" if took_s is not None else ""
        self.panel.results.content = (
            f"Submission {len(handed_in)}{timing}:\n\n{results_markdown(results, score, self.assignment.points)}; "
            f"counted ({self.assignment.counts} of {len(handed_in)}): **{counted:g}**")
