"""Headless assignment commands: ``assignment create``, ``assignment variant``, ``assignment
submit`` and ``grades``.  Bad input raises ``ParameterError`` (the command line prints one line
naming the problem and the valid range, and exits 2)."""

from __future__ import annotations

import json

from app.commands.headless import jsonable, open_store_of, overrides_from
from app.infra import coursework
from app.infra.store_codes import StoreError
from lab_modules.evaluation import assignments
from lab_modules.evaluation.assignments import shown_deadline
from lab_modules.formatting import number
from lab_modules.parameters import ParameterError


def _print(result: dict, as_json: bool, lines: list[str]) -> None:
    if as_json:
        print(json.dumps(jsonable(result), indent=2, ensure_ascii=False))
    else:
        print("\n".join(lines))


def _loaded(store, code):
    try:
        return coursework.load(store, code)
    except StoreError as error:
        raise ParameterError(str(error)) from None


def command_create(args) -> int:
    assignment = assignments.new_assignment(args.exercise, args.title, args.vary, args.lock, args.spec,
                                            args.deadline, args.counts, args.duration,
                                            overrides_from(args.set))
    store = open_store_of(args)
    try:
        code = coursework.create(store, assignment)
    except StoreError as error:
        raise ParameterError(str(error)) from None
    link = coursework.student_link(args.url, code)
    _print({"code": code, "link": link, "assignment": assignment.as_json()}, args.json,
           [(f"assignment {code}: {assignment.title} ({assignment.exercise}, {number(assignment.points)} points, "
            f"deadline {shown_deadline(assignment.deadline)})"), f"student link: {link}"])
    return 0


def command_variant(args) -> int:
    code, assignment = _loaded(open_store_of(args), args.code)
    student = assignments.check_student(args.student)
    drawn = assignments.variant(assignment, code, student)
    _print({"code": code, "student": student, "variant": drawn,
            "changeable": assignments.changeable(assignment)}, args.json,
           [f"{name} = {value}" for name, value in drawn.items()])
    return 0


def command_submit(args) -> int:
    store = open_store_of(args)
    code, assignment = _loaded(store, args.code)
    try:
        submission, results = coursework.submit(store, code, assignment, args.student, overrides_from(args.set))
    except StoreError as error:
        raise ParameterError(str(error)) from None
    counted = assignments.counted_score(assignment, [s.score for s in store.submissions(code, submission.student)])
    _print({"code": code, "student": submission.student, "settings": submission.parameters,
            "results": [coursework.result_json(r) for r in results], "score": submission.score,
            "points": assignment.points, "counted_score": counted, "counts": assignment.counts}, args.json,
           [f"{'pass' if r.passed else 'FAIL'}  {r.metric} = {number(r.value)} ({r.relation} {r.bound:g}): "
            f"{number(r.earned)}/{number(r.points)}" for r in results]
           + [(f"score {number(submission.score)}/{number(assignment.points)}; counted ({assignment.counts}): "
              f"{number(counted)}")])
    return 0


def command_grades(args) -> int:
    store = open_store_of(args)
    for code in args.codes:
        _loaded(store, code)                       # every code checked before anything is printed
    text = coursework.gradebook(store, args.codes, args.lms)
    print(text if args.csv else text.replace(",", "\t"), end="")
    return 0
