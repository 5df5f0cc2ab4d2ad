"""Assignments (lab_modules/evaluation/assignments.py, app/infra/coursework.py, the assignment and
grades commands): variants drawn per student, specs graded on the server by recomputing the
metrics, the gradebook CSV, on SQLite and PostgreSQL."""

from __future__ import annotations

import csv
import io
import json

import pytest

from app.cli import main
from lab_modules.evaluation import assignments
from lab_modules.evaluation.assignments import Assignment, Spec, Variation
from lab_modules.evaluation.gradebook import GradeColumn, gradebook_csv
from lab_modules.parameters import ParameterError

VARY = ["sensor_noise_um=1.0..1.6", "current_noise_a=1.5..2.2"]
SPECS = ["consistency_inside_3sigma_percent>=95:1", "current_noise_reduction_percent>=75:2",
         "max_gain_factor_estimated>=3:2"]
#: Four designs and the specs each meets on every variant of VARY (the filter's consistency, the
#: current noise it removes, the gain margin it leaves): the known subset that passes each spec.
DESIGNS = [
    ({"feedback": "estimated"}, (True, True, True)),                                  # the paper's tuning
    ({"feedback": "estimated", "filter_q_velocity": "1.352e-9"}, (True, False, True)),  # trusts the model less
    ({"feedback": "measured", "pid_gain": "1.3"}, (False, True, False)),              # twice the gain, no filter
    ({"feedback": "estimated", "filter_r_position": "1e-6"}, (False, False, False)),  # overconfident filter
]
POINTS = (1, 2, 2)


def _assignment(**changes) -> Assignment:
    fields = {"exercise": "kalman_noise", "title": "Noise", "locked": ("sensor_lag_us",), "duration_s": 0.5,
              "variations": (Variation("sensor_noise_um", 1.0, 1.6), Variation("current_noise_a", 1.5, 2.2)),
              "specs": (Spec("current_noise_reduction_percent", ">=", 75, 2),)}
    return Assignment(**{**fields, **changes})


# -- pure: variants, specs, grading --------------------------------------------------------------
def test_variants_are_reproducible_distinct_and_inside_their_ranges():
    assignment = _assignment()
    drawn = [assignments.variant(assignment, "KN-AAAA-BBBB-CCCC", f"s{k:02d}") for k in range(30)]
    assert drawn == [assignments.variant(assignment, "KN-AAAA-BBBB-CCCC", f"s{k:02d}") for k in range(30)]
    assert len({tuple(d.values()) for d in drawn}) == 30
    assert all(1.0 <= d["sensor_noise_um"] <= 1.6 and 1.5 <= d["current_noise_a"] <= 2.2 for d in drawn)
    assert assignments.variant(assignment, "KN-AAAA-BBBB-CCCD", "s00") != drawn[0]     # another assignment


def test_a_submission_cannot_change_a_fixed_parameter():
    assignment = _assignment()
    for name in ("sensor_noise_um", "sensor_lag_us"):
        with pytest.raises(ParameterError, match=f"{name} is fixed in this assignment: expected changes to "):
            assignments.student_values(assignment, "KN-AAAA-BBBB-CCCC", "s1", {name: 1.0})
    values = assignments.student_values(assignment, "KN-AAAA-BBBB-CCCC", "s1", {"gain_factor": "2"})
    assert values["gain_factor"] == 2.0 and values["sensor_noise_um"] == \
        assignments.variant(assignment, "KN-AAAA-BBBB-CCCC", "s1")["sensor_noise_um"]


def test_grading_holds_each_spec_to_its_bound_and_fails_an_unmeasured_metric():
    specs = (Spec("a", "<=", 3.0, 2), Spec("b", ">=", 50.0, 1), Spec("c", ">=", 1, 1), Spec("d", "<=", 1, 4))
    results = assignments.grade(specs, {"a": 3.0, "b": 49.9, "c": True, "d": None})
    assert [r.passed for r in results] == [True, False, True, False] and assignments.score(results) == 3
    assert assignments.counted_score(_assignment(), [2, 5, 1]) == 5
    assert assignments.counted_score(_assignment(counts="last"), [2, 5, 1]) == 1
    assert assignments.counted_score(_assignment(), []) is None


@pytest.mark.parametrize(("call", "words"), [
    (lambda: assignments.parse_variation(_exercise(), "sensor_noise_um=1..99"), "out of range: expected 0 ... 10 µm"),
    (lambda: assignments.parse_variation(_exercise(), "sensor_noise_um=2..1"), "LOW must be below HIGH"),
    (lambda: assignments.parse_variation(_exercise(), "nothing=1..2"), "no such parameter: expected one of"),
    (lambda: assignments.parse_variation(_exercise(), "feedback=1..2"), "is a choice"),
    (lambda: assignments.parse_variation(_exercise(), "sensor_noise_um=1"), "is not NAME=LOW..HIGH"),
    (lambda: assignments.parse_spec("rms<3:1"), "is not METRIC<=BOUND:POINTS"),
    (lambda: assignments.parse_spec("rms<=x:1"), "must be numbers"),
    (lambda: assignments.parse_spec("rms<=1:0"), "POINTS in 0 ... 1000"),
    (lambda: assignments.parse_deadline("next friday"), "expected YYYY-MM-DDTHH:MM"),
    (lambda: assignments.check_student("  "), "1 ... 64 printable characters"),
])
def test_bad_assignment_input_names_the_problem_and_the_valid_range(call, words):
    with pytest.raises(ParameterError, match=words.replace("(", r"\(").replace(".", r"\.")):
        call()


def _exercise():
    from lab_modules.exercises import get
    return get("kalman_noise")


def test_gradebook_layouts():
    columns = [GradeColumn("Noise", "KN-A", 5, {"s2": 3.0, "s1": None}), GradeColumn("Gain", "KN-B", 2, {"s1": 2})]
    assert gradebook_csv(columns, "canvas") == (
        "Student,ID,SIS User ID,SIS Login ID,Section,Noise (KN-A),Gain (KN-B)\n"
        "Points Possible,,,,,5,2\n"
        "s1,,s1,,,,2\n"
        "s2,,s2,,,3,\n")
    assert gradebook_csv(columns, "moodle") == "ID number,Noise (KN-A),Gain (KN-B)\ns1,,2\ns2,3,\n"


# -- headless, end to end, on both back ends -----------------------------------------------------
def _where(database) -> list[str]:
    data_dir, url = database
    return ["--database", url] if url else ["--data-dir", str(data_dir)]


def _json(capsys) -> dict:
    return json.loads(capsys.readouterr().out)


def test_thirty_students_graded_headless_into_the_gradebook(database, capsys):
    where = _where(database)
    assert main(["assignment", "create", "--exercise", "kalman_noise", "--title", "Filter noise",
                 *[f"--vary={v}" for v in VARY], "--lock", "sensor_lag_us", *[f"--spec={s}" for s in SPECS],
                 "--duration", "0.5", "--url", "http://lab.example:8080", "--json", *where]) == 0
    created = _json(capsys)
    code = created["code"]
    assert created["link"] == f"http://lab.example:8080/?assignment={code}"
    students = [f"s{k:02d}" for k in range(1, 31)]
    variants = {}
    for student in students:
        assert main(["assignment", "variant", code, "--student", student, "--json", *where]) == 0
        variants[student] = _json(capsys)["variant"]
    assert len({tuple(v.values()) for v in variants.values()}) == 30
    assert main(["assignment", "variant", code, "--student", "s07", "--json", *where]) == 0
    assert _json(capsys)["variant"] == variants["s07"]                     # reproducible
    expected = {}
    for k, student in enumerate(students):
        settings, passes = DESIGNS[k % len(DESIGNS)]
        assert main(["assignment", "submit", code, "--student", student, "--json", *where,
                     *[f"--set={name}={value}" for name, value in settings.items()]]) == 0
        result = _json(capsys)
        assert [r["passed"] for r in result["results"]] == list(passes), (student, result["results"])
        assert result["score"] == sum(p for p, ok in zip(POINTS, passes, strict=True) if ok)
        expected[student] = result["score"]
    # a later, worse submission does not lower the best score that counts
    assert main(["assignment", "submit", code, "--student", "s01", "--set", "filter_r_position=1e-6",
                 "--json", *where]) == 0
    assert _json(capsys)["counted_score"] == 5
    assert main(["grades", code, "--csv", *where]) == 0
    rows = list(csv.reader(io.StringIO(capsys.readouterr().out)))
    assert rows[0] == ["Student", "ID", "SIS User ID", "SIS Login ID", "Section", f"Filter noise ({code})"]
    assert rows[1] == ["Points Possible", "", "", "", "", "5"]
    assert {row[2]: float(row[5]) for row in rows[2:]} == expected
    assert sorted(expected.values()) == sorted([5.0] * 8 + [3.0] * 8 + [2.0] * 7 + [0.0] * 7)


@pytest.mark.parametrize(("argv", "words"), [
    (["assignment", "create", "--exercise", "kalman_noise", "--spec", "nope>=1:1"],
     "measures no number 'nope': expected one of"),
    (["assignment", "create", "--exercise", "kalman_noise", "--vary", "gain_factor=0..9", "--spec", "mean>=1:1"],
     "gain_factor='0' is out of range: expected 0.1 ... 4"),
    (["assignment", "create", "--exercise", "kalman_noise"], "needs at least one --spec"),
    (["assignment", "variant", "KN-0000", "--student", "s1"], "is not an assignment code"),
    (["assignment", "variant", "KN-AAAA-BBBB-CCCC", "--student", "s1"], "no assignment has the code"),
    (["grades", "KN-AAAA-BBBB-CCCC", "--csv"], "no assignment has the code"),
])
def test_bad_assignment_commands_exit_2_with_one_line(argv, words, tmp_path, capsys):
    assert main([*argv, "--data-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1, err


def test_fixed_parameters_and_the_deadline_are_enforced(tmp_path, capsys):
    where = ["--data-dir", str(tmp_path)]
    create = ["assignment", "create", "--exercise", "kalman_noise", "--vary", VARY[0], "--spec", SPECS[1],
              "--duration", "0.2", "--json", *where]
    assert main(create) == 0
    code = _json(capsys)["code"]
    assert main(["assignment", "submit", code, "--student", "s1", "--set", "sensor_noise_um=0", *where]) == 2
    err = capsys.readouterr().err
    assert "sensor_noise_um is fixed in this assignment: expected changes to current_noise_a, disturbance_force_n" in err
    assert main([*create, "--deadline", "2020-01-01T00:00+00:00"]) == 0
    closed = _json(capsys)["code"]
    assert main(["assignment", "submit", closed, "--student", "s1", *where]) == 2
    err = capsys.readouterr().err
    assert f"the deadline of {closed} (2020-01-01 00:00 UTC) has passed" in err and err.count("\n") == 1
