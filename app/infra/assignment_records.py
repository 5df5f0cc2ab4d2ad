"""Assignments, the students who opened them and their submissions, kept by the store
(``app/infra/store.py``) in the tables of schema version 2 (``app/infra/schema.py``).

The store keeps what it is given: an assignment's definition and a submission's graded
results are JSON made by the evaluation (``lab_modules/evaluation``); grading happens there,
never here, and never from numbers a browser sent."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass

from app.infra.store_codes import StoreError, StoreUnavailable, normalise_code


@dataclass(frozen=True)
class Submission:
    """One graded submission: the settings the student chose, each spec's result as graded
    on the server, the points scored and when (s since the epoch)."""

    id: int
    assignment: str
    student: str
    parameters: dict
    results: list
    score: float
    submitted: float


class AssignmentRecords:
    """The assignment tables; mixed into ``Store``, whose ``_using``, ``_execute`` and
    ``insert_with_new_code`` it uses, so both back ends share it."""

    def create_assignment(self, prefix: str, definition: dict) -> str:
        """Store a new assignment's ``definition`` (JSON-able) under a fresh code with ``prefix``."""
        with self._using(write=True) as db:
            return self.insert_with_new_code(db, prefix, "INSERT INTO assignments VALUES (?, ?, ?) "
                                             "ON CONFLICT DO NOTHING", (json.dumps(definition), time.time()))

    def assignment(self, code: str) -> tuple[str, dict]:
        """(code as stored, definition) of the assignment ``code`` (typed in any case), or ``StoreError``."""
        code = normalise_code(code, "assignment")
        with self._using() as db:
            row = self._execute(db, "SELECT definition FROM assignments WHERE code = ?", (code,)).fetchone()
        if row is None:
            raise StoreError(f"no assignment has the code {code}")
        return code, _decoded(row[0], code)

    def join(self, code: str, student: str) -> None:
        """Record that ``student`` opened the assignment (once; later calls change nothing)."""
        with self._using(write=True) as db:
            self._execute(db, "INSERT INTO assignment_students VALUES (?, ?, ?) ON CONFLICT DO NOTHING",
                          (code, student, time.time()))

    def students(self, code: str) -> list[str]:
        """Everyone who opened or was graded on the assignment, in the order they first came."""
        with self._using() as db:
            rows = self._execute(db, "SELECT student FROM assignment_students WHERE assignment = ? "
                                 "ORDER BY joined, student", (code,)).fetchall()
        return [row[0] for row in rows]

    def add_submission(self, code: str, student: str, parameters: dict, results: list,
                       score: float) -> Submission:
        """Keep one graded submission (and the student, if new); returns it as stored."""
        now = time.time()
        with self._using(write=True) as db:
            self._execute(db, "INSERT INTO assignment_students VALUES (?, ?, ?) ON CONFLICT DO NOTHING",
                          (code, student, now))
            row = self._execute(
                db, "INSERT INTO submissions (assignment, student, parameters, results, score, submitted) "
                "VALUES (?, ?, ?, ?, ?, ?) RETURNING id",
                (code, student, json.dumps(parameters, sort_keys=True), json.dumps(results), float(score),
                 now)).fetchone()
        return Submission(row[0], code, student, parameters, results, float(score), now)

    def submissions(self, code: str, student: str | None = None) -> list[Submission]:
        """The assignment's submissions (of one ``student``, or everyone's), oldest first."""
        query = ("SELECT id, assignment, student, parameters, results, score, submitted FROM submissions "
                 "WHERE assignment = ?")
        values: tuple = (code,)
        if student is not None:
            query, values = query + " AND student = ?", (code, student)
        with self._using() as db:
            rows = self._execute(db, query + " ORDER BY submitted, id", values).fetchall()
        return [Submission(row[0], row[1], row[2], _decoded(row[3], code), _decoded(row[4], code), row[5], row[6])
                for row in rows]


def _decoded(text: str, code: str):
    try:
        return json.loads(text)
    except ValueError:
        raise StoreUnavailable(f"the stored data of {code} are damaged") from None
