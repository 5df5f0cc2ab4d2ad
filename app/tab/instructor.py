"""A tab as an assignment's instructor page (``?instructor=CODE``), or the form for a new one
(``?instructor`` without a code): behind the instructor token, which is compared on the server
and never sent to any tab; wrong tries count like wrong class tokens (per tab, then per address
across tabs).  Once in, the tab's lab stops and the page shows the class, refreshing every
``REFRESH_S`` on the tab's worker, or the form."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from app.infra import coursework
from app.infra.access import Throttle, token_matches
from app.infra.store import Store, StoreError
from app.panels.assignment_form import (
    AssignmentForm,
    AssignmentRequest,
    created_markdown,
    exercise_markdown,
    in_form_words,
)
from app.panels.assignment_instructor import (
    InstructorGate,
    InstructorPage,
    link_markdown,
    standings_markdown,
    submission_label,
)
from app.panels.text import escaped
from app.tab.gate import TOKEN_ATTEMPTS, TOKEN_RETRY_S
from app.tab.worker import TabClosed, TabWorker
from lab_modules.evaluation import assignments
from lab_modules.evaluation.assignments import Assignment
from lab_modules.exercises import get, registry
from lab_modules.parameters import ParameterError

REFRESH_S = 2.0                   # the page looks for new submissions this often


class InstructorTab:
    """The instructor page of one tab (None until the token was right)."""

    def __init__(self, store: Store | None, client, gui_lock, worker: TabWorker, token: str | None,
                 leave_lab: Callable[[], None], refuse: Callable[[str], None], tries: Throttle | None = None,
                 address: str = "unknown"):
        """``leave_lab()`` stops the tab's lab and clears its GUI; ``refuse(reason)`` disconnects the tab."""
        self.store, self.client, self.gui_lock, self.worker, self.token = store, client, gui_lock, worker, token
        self.leave_lab, self.refuse, self.tries, self.address = leave_lab, refuse, tries, address
        self.attempts = 0
        self.gate: InstructorGate | None = None
        self.page: InstructorPage | None = None
        self.code: str | None = None
        self.assignment: Assignment | None = None
        self.listed: dict[str, object] = {}       # dropdown label -> submission
        self.form: AssignmentForm | None = None
        self.metrics_of_defaults: dict[str, dict] = {}   # exercise -> one run's metrics (the specs' names)

    def offer(self, code: str, warn: Callable[[str], None]) -> None:
        """The link asks for the instructor page: the gate (``warn``: a line in the tab)."""
        if self.store is None or self.token is None:
            warn("⚠️ This lab has no instructor page (no store or no instructor token).")
            return
        if self.gate is None and self.page is None:
            with self.gui_lock:
                self.gate = InstructorGate(self.client.gui, code, self.check, self.worker.on)

    def check(self, token: str, code: str) -> None:
        """The gate's button: a right token and a known code open the page."""
        if self.page is not None or self.form is not None:
            return
        wait_s = self.tries.wait_s(self.address) if self.tries is not None else 0.0
        if wait_s > 0:
            self.gate.message.content = f"⚠️ Too many wrong tokens from your network: try again in {wait_s:.0f} s."
            return
        if not token_matches(self.token, token):
            if self.tries is not None:
                self.tries.failed(self.address)
            self.attempts += 1
            if self.attempts >= TOKEN_ATTEMPTS:
                self.refuse("too many wrong instructor tokens")
                raise TabClosed
            time.sleep(TOKEN_RETRY_S)             # guessing costs time
            self.gate.message.content = (f"⚠️ That is not the instructor token ({TOKEN_ATTEMPTS - self.attempts} "
                                         "tries left).")
            return
        if not code.strip():
            self._open_form()
            return
        try:
            self.code, self.assignment = coursework.load(self.store, code)
        except StoreError as error:
            self.gate.message.content = f"⚠️ {escaped(error)}"
            return
        self.gate.close()
        self.gate = None
        self.leave_lab()
        with self.gui_lock:
            self.page = InstructorPage(self.client.gui, self.assignment, self.code, self.worker.on, self.export,
                                       self.open_submission)
        self.refresh()
        threading.Thread(target=self._keep_fresh, name=f"{self.worker.name}-instructor", daemon=True).start()

    def _open_form(self) -> None:
        """The form for a new assignment, on the first exercise."""
        self.gate.close()
        self.gate = None
        self.leave_lab()
        exercises = registry()
        with self.gui_lock:
            self.form = AssignmentForm(self.client.gui, exercises, self.worker.on, self.create, self.describe)
        self.describe(next(iter(exercises)))

    def describe(self, name: str) -> None:
        """The chosen exercise's parameters and gradable metrics (one run on its defaults, once)."""
        exercise = get(name)
        if name not in self.metrics_of_defaults:
            values = exercise.resolve({})
            values.pop("data", None)
            self.metrics_of_defaults[name] = exercise.metrics(values, exercise.default_duration_s)
        metrics = [m for m, value in self.metrics_of_defaults[name].items() if assignments.gradable(value)]
        with self.gui_lock:
            self.form.about.content = exercise_markdown(exercise, metrics)

    def create(self, request: AssignmentRequest) -> None:
        """Check the form as the command line would, keep the assignment, give its links."""
        try:
            assignment = assignments.new_assignment(
                request.exercise, request.title or None, request.varied, request.locked, request.specs,
                request.deadline, request.counts, metrics_of_defaults=self.metrics_of_defaults.get(request.exercise))
            code = coursework.create(self.store, assignment)
        except (ParameterError, StoreError) as error:
            message = f"⚠️ {escaped(in_form_words(str(error)))}"
        else:
            message = created_markdown(code, assignment.title, assignment.points)
        with self.gui_lock:
            self.form.message.content = message

    def _keep_fresh(self) -> None:
        while not self.worker.closed:
            time.sleep(REFRESH_S)
            self.worker.post("instructor refresh", self.refresh)

    def refresh(self) -> None:
        """The class as the store has it now."""
        rows = coursework.standings(self.store, self.code, self.assignment)
        counts: dict[str, int] = {}
        self.listed = {}
        for submission in self.store.submissions(self.code):
            counts[submission.student] = counts.get(submission.student, 0) + 1
            self.listed[submission_label(submission, counts[submission.student])] = submission
        with self.gui_lock:
            self.page.show(standings_markdown(self.assignment, rows), tuple(self.listed))

    def export(self, layout: str) -> None:
        """The gradebook of this assignment, as the LMS imports it, sent as a file."""
        text = coursework.gradebook(self.store, [self.code], layout)
        self.client.send_file_download(f"gradebook_{self.code}_{layout}.csv", text.encode(), save_immediately=True)
        self.page.note.content = f"Sent the {layout.capitalize()} gradebook ({len(self.store.students(self.code))} " \
            "students)."

    def open_submission(self, label: str) -> None:
        """Keep the submission as a saved experiment (the student's variant and settings) and give
        the link that opens it as a lab tab."""
        submission = self.listed.get(label)
        if submission is None:
            self.page.note.content = "*Choose a submission first.*"
            return
        values = assignments.student_values(self.assignment, self.code, submission.student, submission.parameters)
        values.pop("data", None)
        code = self.store.save(self.assignment.exercise, values)
        self.page.note.content = link_markdown(label, code)
