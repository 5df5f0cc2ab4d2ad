"""The gradebook an LMS imports: one row per student, one column per assignment, as CSV.

* ``canvas``: Canvas's gradebook export layout (Student, ID, SIS User ID, SIS Login ID, Section,
  then one ``Title (code)`` column per assignment, and a "Points Possible" row under the header);
  Canvas matches rows by SIS User ID, which holds the id the student gave.
* ``moodle``: Moodle's "Import grades: CSV file" (an "ID number" column to map to the user's ID
  number, then one column per assignment to map to its grade item).

A student without a submission to an assignment has an empty cell (not graded), not 0."""

from __future__ import annotations

import csv
import io
from dataclasses import dataclass

LAYOUTS = ("canvas", "moodle")
CANVAS_IDENTITY = ("Student", "ID", "SIS User ID", "SIS Login ID", "Section")


@dataclass(frozen=True)
class GradeColumn:
    """One assignment's column: its title, code, points possible and the score of each student."""

    title: str
    code: str
    points: float
    scores: dict[str, float | None]

    @property
    def heading(self) -> str:
        return f"{self.title} ({self.code})"


def _cell(score: float | None) -> str:
    return "" if score is None else f"{score:g}"


def gradebook_csv(columns: list[GradeColumn], layout: str = "canvas") -> str:
    """The CSV text (students sorted by id; every student of any column gets a row)."""
    if layout not in LAYOUTS:
        raise ValueError(f"gradebook layout {layout!r}: expected one of {', '.join(LAYOUTS)}")
    students = sorted({student for column in columns for student in column.scores})
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    if layout == "canvas":
        writer.writerow([*CANVAS_IDENTITY, *(c.heading for c in columns)])
        writer.writerow(["Points Possible", "", "", "", "", *(f"{c.points:g}" for c in columns)])
        for student in students:
            writer.writerow([student, "", student, "", "", *(_cell(c.scores.get(student)) for c in columns)])
    else:
        writer.writerow(["ID number", *(c.heading for c in columns)])
        for student in students:
            writer.writerow([student, *(_cell(c.scores.get(student)) for c in columns)])
    return text.getvalue()
