"""Assignments end to end, for the command line and the browser alike: create one, draw a
student's variant, grade and keep a submission, the class's standing and its gradebook.

The evaluation (variants, specs, grading from recomputed metrics) is
``lab_modules.evaluation.assignments``; this module joins it to the store.  A submission carries
settings only; it is graded here on the server, on the student's own variant."""

from __future__ import annotations

import time
from dataclasses import dataclass

from app.infra.assignment_records import Submission
from app.infra.store import Store
from app.infra.store_codes import code_prefix
from lab_modules.evaluation import assignments
from lab_modules.evaluation.assignments import Assignment, SpecResult
from lab_modules.evaluation.gradebook import GradeColumn, gradebook_csv
from lab_modules.parameters import ParameterError


def create(store: Store, assignment: Assignment) -> str:
    """Keep ``assignment``; its code."""
    return store.create_assignment(code_prefix(assignment.exercise), assignment.as_json())


def load(store: Store, code: str) -> tuple[str, Assignment]:
    """(code as stored, assignment); ``StoreError`` for an unknown or malformed code."""
    code, definition = store.assignment(code)
    return code, Assignment.from_json(definition)


def student_link(base_url: str, code: str) -> str:
    """The address students open: the lab with the assignment's code in the query."""
    return f"{base_url.rstrip('/')}/?assignment={code}"


def submit(store: Store, code: str, assignment: Assignment, student: str, settings: dict,
           now: float | None = None) -> tuple[Submission, list[SpecResult]]:
    """Grade ``settings`` on the student's variant (the metrics recomputed here) and keep the
    result; ``ParameterError`` after the deadline or for a fixed parameter."""
    student = assignments.check_student(student)
    if assignment.is_closed(time.time() if now is None else now):
        raise ParameterError(f"the deadline of {code} ({assignments.shown_deadline(assignment.deadline)}) has "
                             "passed: no more submissions")
    values, results = assignments.grade_submission(assignment, code, student, settings)
    chosen = {name: values[name] for name in settings}
    stored = store.add_submission(code, student, chosen, [result_json(r) for r in results],
                                  assignments.score(results))
    return stored, results


def result_json(result: SpecResult) -> dict:
    return {"metric": result.metric, "relation": result.relation, "bound": result.bound,
            "points": result.points, "value": result.value, "passed": result.passed}


@dataclass(frozen=True)
class Standing:
    """One student in the instructor's view: the drawn plant, how many submissions, the score
    that counts and the per-spec results of the submission it comes from."""

    student: str
    variant: dict
    submissions: int
    score: float | None
    results: list


def standings(store: Store, code: str, assignment: Assignment) -> list[Standing]:
    """Every student who opened or submitted to the assignment, in the order they came."""
    by_student: dict[str, list[Submission]] = {student: [] for student in store.students(code)}
    for submission in store.submissions(code):
        by_student.setdefault(submission.student, []).append(submission)
    rows = []
    for student, handed_in in by_student.items():
        counted = assignments.counted_score(assignment, [s.score for s in handed_in])
        chosen = None
        if handed_in:
            chosen = handed_in[-1] if assignment.counts == "last" else max(handed_in, key=lambda s: s.score)
        rows.append(Standing(student, assignments.variant(assignment, code, student), len(handed_in), counted,
                             chosen.results if chosen else []))
    return rows


def gradebook(store: Store, codes: list[str], layout: str = "canvas") -> str:
    """The gradebook CSV of one or more assignments (one column each)."""
    columns = []
    for typed in codes:
        code, assignment = load(store, typed)
        scores = {row.student: row.score for row in standings(store, code, assignment)}
        columns.append(GradeColumn(assignment.title, code, assignment.points, scores))
    return gradebook_csv(columns, layout)
