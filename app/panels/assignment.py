"""What a student sees of an assignment: the dialog that asks for their name or student id, the
"Assignment" folder with the Submit button and each spec's result beside it, and the fixed
controls (disabled, with a hint saying why).

Only rendering: the results shown are those graded on the server (``app.infra.coursework``)."""

from __future__ import annotations

from collections.abc import Callable

from app.panels.text import escaped
from lab_modules.evaluation.assignments import Assignment, shown_deadline
from lab_modules.formatting import number

DRAWN_HINT = "Your own plant in this assignment: drawn for you from your id, so it cannot be changed."
LOCKED_HINT = "Fixed by your instructor in this assignment."
PASSED, FAILED = "✓ pass", "✗ fail"      # signs every font has (emoji are boxes without an emoji font)
SUBMIT_HINT = ("Grades the settings now in this tab: the lab runs your design again on the server, on your "
               "plant, and holds each result to its bound. You may submit again until the deadline.")


def shown_relation(relation: str) -> str:
    return {"<=": "≤", ">=": "≥"}[relation]


def specs_markdown(assignment: Assignment) -> str:
    """The specs to meet, the deadline and which submission counts."""
    rows = "\n".join(f"| {escaped(spec.metric)} | {shown_relation(spec.relation)} {number(spec.bound)} | "
                     f"{number(spec.points)} |" for spec in assignment.specs)
    return (f"| spec | bound | points |\n|---|---|---:|\n{rows}\n\n"
            f"Deadline: {shown_deadline(assignment.deadline)}; the {assignment.counts} submission counts "
            f"({number(assignment.points)} points).")


def results_markdown(results: list[dict], score: float, points: float) -> str:
    """Each spec's value on the student's plant and whether it passed (as graded on the server)."""
    rows = "\n".join(
        f"| {escaped(r['metric'])} {shown_relation(r['relation'])} {number(r['bound'])} | "
        f"{'—' if r['value'] is None else number(r['value'])} | {PASSED if r['passed'] else FAILED} "
        f"{number(r['points'] if r['passed'] else 0)}/{number(r['points'])} |" for r in results)
    return (f"| spec | value | result |\n|---|---:|---|\n{rows}\n\n"
            f"**Score {number(score)}/{number(points)}**")


class JoinDialog:
    """A modal: the assignment, a box for the student's name or id, a button, one line of reply."""

    def __init__(self, gui, assignment: Assignment, code: str, student: str, join: Callable[[str], None], on):
        """``join(student)`` runs on the tab's worker (``on(key, action)``)."""
        self.modal = gui.add_modal(f"Assignment: {assignment.title}")
        with self.modal:
            gui.add_markdown(f"Code **{escaped(code)}**, exercise *{escaped(assignment.exercise)}*. Your own plant is "
                             "drawn from your id: give the same id every time (it is also how you are graded).\n\n"
                             + specs_markdown(assignment))
            self.student = gui.add_text("Name or student id", student,
                                        hint="As your instructor asks for it (e.g. your student number).")
            button = gui.add_button("Start the assignment")
            self.message = gui.add_markdown("")
        button.on_click(on("assignment join", lambda: join(self.student.value)))

    def close(self) -> None:
        self.modal.close()


class SubmitPanel:
    """The "Assignment" folder at the top of the controls: who and what, Submit, the results."""

    def __init__(self, gui, assignment: Assignment, code: str, student: str, submit: Callable[[], None], on):
        with gui.add_folder("Assignment"):
            gui.add_markdown(f"**{escaped(assignment.title)}** ({escaped(code)}), as **{escaped(student)}**. "
                             "Greyed controls are fixed; change the others, then submit.\n\n"
                             + specs_markdown(assignment))
            self.button = gui.add_button("Submit", hint=SUBMIT_HINT)
            self.results = gui.add_markdown("")
        self.button.on_click(on("assignment submit", submit))


def fix_controls(inputs: dict, entries: dict, assignment: Assignment, chooser) -> None:
    """Disable the controls of the parameters the assignment fixes, with a hint saying why, and the
    exercise chooser (the assignment is one exercise)."""
    drawn = {variation.parameter for variation in assignment.variations}
    for name in assignment.fixed:
        for handle in {id(h): h for h in (inputs.get(name), entries.get(name)) if h is not None}.values():
            handle.disabled = True
            handle.hint = DRAWN_HINT if name in drawn else LOCKED_HINT
    chooser.disabled = True
    chooser.hint = "This tab is your assignment; open another tab for the other exercises."
