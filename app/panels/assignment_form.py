"""The instructor's form for a new assignment (``?instructor`` without a code): the same parts as
``python -m app assignment create`` (exercise, title, parameters drawn per student, locked
parameters, specs, deadline, best or last), one per line where there may be several, with the
chosen exercise's parameters and gradable metrics listed beside them.

Only rendering and the form's controls; ``app/tab/instructor.py`` checks and creates."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from app.panels.assignment_instructor import PAGE_WIDTH_PX
from app.panels.text import escaped
from lab_modules.evaluation.assignments import COUNTS, SPEC_FORM, VARY_FORM
from lab_modules.exercises import Exercise
from lab_modules.formatting import number

#: the command line's option names in the checks' messages, as the form calls them
FIELD_NAMES = {"--vary": "Drawn per student:", "--lock": "Locked:", "--spec": "Specs:",
               "--deadline": "Deadline:", "--counts": "Counts:", "--duration": "Run length:"}


@dataclass(frozen=True)
class AssignmentRequest:
    """What the form holds, as ``assignments.new_assignment`` takes it."""

    exercise: str
    title: str
    varied: list[str]
    locked: list[str]
    specs: list[str]
    deadline: str | None
    counts: str


def lines(text: str) -> list[str]:
    """The non-empty lines (or comma-separated parts) of a box."""
    return [part.strip() for line in text.splitlines() for part in line.split(",") if part.strip()]


def in_form_words(message: str) -> str:
    """A check's message with the form's field names for the command line's options."""
    for option, field in FIELD_NAMES.items():
        message = message.replace(option, field)
    return message


def exercise_markdown(exercise: Exercise, metrics: list[str]) -> str:
    """The exercise's parameters (name, range, default) and the metrics a spec may hold to a bound."""
    rows = [f"| `{p.name}` | {escaped(p.label)} | {escaped(p.valid_range())} | "
            f"{escaped(p.default if p.choices else f'{p.default:.4g}')} |" for p in exercise.parameters if p.name != "data"]
    return ("**Parameters** (drawn or locked by name):\n\n| name | control | range | default |\n|---|---|---|---|\n"
            + "\n".join(rows) + "\n\n**Metrics a spec can grade:** " + ", ".join(f"`{m}`" for m in metrics))


def created_markdown(code: str, title: str, points: float) -> str:
    """The new assignment's code and its two links (relative: they keep this page's address)."""
    return (f"Created **{escaped(code)}**: {escaped(title)} ({number(points)} points).\n\n"
            f"- Student link: [?assignment={code}](?assignment={code}) (give it to the class)\n"
            f'- Its instructor page: <a href="?instructor={code}" target="_blank" rel="noopener">'
            f"?instructor={code}</a>")


class AssignmentForm:
    """The form's controls; ``create(request)`` and ``describe(exercise name)`` run on the tab's worker."""

    def __init__(self, gui, exercises: dict[str, Exercise], on, create: Callable[[AssignmentRequest], None],
                 describe: Callable[[str], None]):
        gui.main_panel.set_width(PAGE_WIDTH_PX)
        gui.add_markdown("## New assignment\nEvery student gets their own plant, drawn from the ranges below; "
                         "a submission is graded on the server by what the design achieves.")
        titles = {exercise.title: name for name, exercise in exercises.items()}
        self.exercise = gui.add_dropdown("Exercise", tuple(titles))
        self.title = gui.add_text("Title", "", hint="Shown to the students (the exercise's title if empty).")
        self.varied = gui.add_text("Drawn per student", "", multiline=True, hint=f"One per line: {VARY_FORM}.")
        self.locked = gui.add_text("Locked", "", hint="Parameter names, comma-separated: the students cannot "
                                                      "change them (the drawn ones are locked anyway).")
        self.specs = gui.add_text("Specs", "", multiline=True, hint=f"One per line: {SPEC_FORM}.")
        self.deadline = gui.add_text("Deadline", "", hint="YYYY-MM-DDTHH:MM (server time unless it names its "
                                                          "zone); empty: none.")
        self.counts = gui.add_dropdown("Counts", COUNTS, hint="Which submission of a student counts.")
        button = gui.add_button("Create the assignment")
        self.message = gui.add_markdown("")
        self.about = gui.add_markdown("")
        self.exercise.on_update(on("assignment form exercise", lambda: describe(titles[self.exercise.value])))
        button.on_click(on("create assignment", lambda: create(AssignmentRequest(
            titles[self.exercise.value], self.title.value, lines(self.varied.value), lines(self.locked.value),
            [line.strip() for line in self.specs.value.splitlines() if line.strip()],
            self.deadline.value.strip() or None, self.counts.value))))
