"""The instructor page of an assignment: the class's students with their variants, submissions,
per-spec results and the score that counts (``coursework.standings``), the gradebook for the LMS
as a download, and a student's submission opened as a lab tab.

Only rendering and the page's controls; ``app/tab/instructor.py`` fills them in."""

from __future__ import annotations

import time
from collections.abc import Callable

from app.infra.assignment_records import Submission
from app.infra.coursework import Standing
from app.panels.assignment import FAILED, PASSED, shown_relation, specs_markdown
from app.panels.text import escaped
from lab_modules.evaluation.assignments import Assignment
from lab_modules.formatting import number

PAGE_WIDTH_PX = 1100              # the table of a class beside nothing else: the page is the left panel
NO_SUBMISSION = "(no submission yet)"


class InstructorGate:
    """A modal asking the instructor token and the assignment's code (never the class token)."""

    def __init__(self, gui, code: str, check: Callable[[str, str], None], on):
        """``check(token, code)`` runs on the tab's worker (``on(key, action)``)."""
        self.modal = gui.add_modal("Instructor page")
        with self.modal:
            gui.add_markdown("The assignment's students, submissions and gradebook. Enter the **instructor "
                             "token** the lab's server printed at start (not the class token); leave the "
                             "code empty to create a new assignment.")
            self.token = gui.add_text("Instructor token", "")
            self.code = gui.add_text("Assignment code", code)
            button = gui.add_button("Open the instructor page")
            self.message = gui.add_markdown("")
        button.on_click(on("instructor token", lambda: check(self.token.value, self.code.value)))

    def close(self) -> None:
        self.modal.close()


def _result_cell(result: dict) -> str:
    value = "—" if result["value"] is None else number(result["value"])
    return f"{value} {PASSED if result['passed'] else FAILED}"


def standings_markdown(assignment: Assignment, rows: list[Standing]) -> str:
    """One row per student: the drawn plant, how many submissions, the score that counts and each
    spec's value (✅/❌) in the submission it comes from."""
    if not rows:
        return "*No student has opened the assignment yet.*"
    specs = [f"{escaped(spec.metric)} {shown_relation(spec.relation)} {number(spec.bound)}" for spec in assignment.specs]
    head = f"| student | variant | submissions | score | {' | '.join(specs)} |\n|---|---|---|---|" + "---|" * len(specs)
    lines = []
    for row in rows:
        variant = ", ".join(f"{name} = {value:g}" for name, value in row.variant.items()) or "—"   # as drawn
        cells = [_result_cell(r) for r in row.results] or ["—"] * len(specs)
        score = "—" if row.score is None else f"{number(row.score)}/{number(assignment.points)}"
        lines.append(f"| {escaped(row.student)} | {variant} | {row.submissions} | {score} | {' | '.join(cells)} |")
    return head + "\n" + "\n".join(lines)


def submission_label(submission: Submission, number_of_student: int) -> str:
    """How a submission is listed: student, its number, score and time (UTC)."""
    at = time.strftime("%H:%M:%S", time.gmtime(submission.submitted))
    return f"{submission.student} · #{number_of_student} · {number(submission.score)} points · {at} UTC"


class InstructorPage:
    """The page's elements: heading, standings, export buttons, a submission to open."""

    def __init__(self, gui, assignment: Assignment, code: str, on, export: Callable[[str], None],
                 open_submission: Callable[[str], None]):
        gui.main_panel.set_width(PAGE_WIDTH_PX)
        gui.add_markdown(f"## {escaped(assignment.title)} ({escaped(code)})\nExercise *{escaped(assignment.exercise)}*.\n\n"
                         f"{specs_markdown(assignment)}\n\nThe table follows new submissions by itself.")
        self.standings = gui.add_markdown("")
        exports = gui.add_button_group("Gradebook (CSV)", ("Canvas", "Moodle"))
        exports.on_click(on("gradebook", lambda: export(exports.value.lower())))
        self.submissions = gui.add_dropdown("Submission", (NO_SUBMISSION,),
                                            hint="A student's submission, to open as a lab tab of its own.")
        opener = gui.add_button("Open as a lab tab")
        opener.on_click(on("open submission", lambda: open_submission(self.submissions.value)))
        self.note = gui.add_markdown("")

    def show(self, standings: str, labels: tuple[str, ...]) -> None:
        """New content only where it changed (the page refreshes every few seconds)."""
        if self.standings.content != standings:
            self.standings.content = standings
        labels = labels or (NO_SUBMISSION,)
        if tuple(self.submissions.options) != labels:
            chosen = self.submissions.value
            self.submissions.options = labels
            self.submissions.value = chosen if chosen in labels else labels[-1]


def link_markdown(label: str, code: str) -> str:
    """A link that opens the saved experiment ``code`` in a new browser tab (``?experiment=CODE``)."""
    return (f'<a href="?experiment={code}" target="_blank" rel="noopener">Open {escaped(label)} '
            f"in a new tab</a> (saved experiment **{escaped(code)}**).")
