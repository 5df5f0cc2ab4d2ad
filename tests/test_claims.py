"""Every paper claim of every registered exercise holds (``lab_modules/claims.py``).

One test per claim; claims measured on the same run (exercise, settings,
duration) share one ``metrics`` call through a module-wide cache, so the
whole file costs one headless run per distinct setting."""

from __future__ import annotations

import html
import json
from pathlib import Path

import pytest

from app.cli import main
from lab_modules.claims import PENDING, WORKSHEET_MARKER, Claim, markdown_table, render_worksheet
from lab_modules.exercises import claim_run, measure_claims
from tests.example_exercise import contract_exercises

ROOT = Path(__file__).resolve().parents[1]
EXERCISES = contract_exercises()          # the registered ones and the tests' minimal example
CLAIMS = [(name, index) for name, exercise in EXERCISES.items() for index in range(len(exercise.claims))]
RUNS: dict = {}          # claim_run key -> metrics, shared by every test in this module


@pytest.mark.parametrize("name", sorted(EXERCISES))
def test_every_exercise_states_at_least_three_claims(name):
    claims = EXERCISES[name].claims
    assert len(claims) >= 3
    for claim in claims:
        assert isinstance(claim, Claim) and claim.source and claim.quantity and claim.paper
        low, high = claim.accept
        assert low is not None or high is not None, claim.quantity
        assert not claim.deviation or claim.note, f"a deviation needs its reason: {claim.quantity}"
        EXERCISES[name].resolve(claim.settings)           # settings name real parameters in range


@pytest.mark.parametrize("name, index", CLAIMS,
                         ids=[f"{name}-{EXERCISES[name].claims[i].metric}-{i}" for name, i in CLAIMS])
def test_claim_holds(name, index):
    exercise = EXERCISES[name]
    claim = exercise.claims[index]
    key = claim_run(exercise, claim)
    if key not in RUNS:
        _, settings, duration = key
        RUNS[key] = exercise.metrics(exercise.resolve(dict(settings)), duration)
    value = claim.value_in(RUNS[key])              # KeyError: the metric does not exist
    assert claim.holds(value), f"{claim.quantity}: {value:g} {claim.unit} outside {claim.accept_text()}"


@pytest.mark.parametrize("name", sorted(EXERCISES))
def test_worksheet_renders_its_table_from_the_claims(name):
    """The worksheet holds the marker (no hand-typed paper-vs-lab table) and the
    table has one row per claim, '…' while nothing is measured."""
    exercise = EXERCISES[name]
    text = (ROOT / "static" / "worksheets" / exercise.worksheet).read_text(encoding="utf-8")
    assert WORKSHEET_MARKER in text.splitlines()
    table = markdown_table(exercise.claims)
    rendered = render_worksheet(text, table)
    assert WORKSHEET_MARKER not in rendered and table in rendered
    assert sum(line.startswith("| ") for line in table.splitlines()) == len(exercise.claims) + 1
    assert table.count(PENDING) >= 2 * len(exercise.claims)          # lab value and status pending


def test_claims_are_measured_once_per_run():
    """measure_claims groups claims by (exercise, settings, duration)."""
    calls = []

    class Counting:
        name, default_duration_s, parameters = "counting", 1.0, ()
        claims = (Claim("s", "a", "1", "a", (0, None), ""), Claim("s", "b", "1", "b.1", (0, None), ""),
                  Claim("s", "c", "1", "a", (0, None), "", settings={"x": 2}))

        def resolve(self, overrides):
            return dict(overrides)

        def metrics(self, values, duration_s):
            calls.append((values, duration_s))
            return {"a": values.get("x", 1), "b": [0, 5]}

    assert measure_claims(Counting()) == [1.0, 5.0, 2.0]
    assert calls == [({}, 1.0), ({"x": 2}, 1.0)]


def test_a_failing_or_missing_claim_is_reported():
    claim = Claim("s", "q", "1", "a.b", (1, 2), "%")
    assert claim.value_in({"a": {"b": 1.5}}) == 1.5 and claim.holds(1.5)
    assert not claim.holds(2.5) and not claim.holds(float("nan"))
    with pytest.raises(KeyError):
        claim.value_in({"a": {}})
    assert "FAIL" in markdown_table((claim,), [2.5]) and "pass" in markdown_table((claim,), [1.5])


def test_reproduce_prints_json_and_writes_the_report(tmp_path, capsys):
    status = main(["reproduce", "--quick", "--json", "--exercise", "lqg_vs_pid", "--html", str(tmp_path)])
    report = json.loads(capsys.readouterr().out)
    assert status == 0
    rows = report["claims"]
    assert len(rows) == len(EXERCISES["lqg_vs_pid"].claims)
    assert all(row["status"] in ("pass", "deviation (holds)") for row in rows)
    page = (tmp_path / "index.html").read_text(encoding="utf-8")
    assert page.count("data:image/png;base64,") >= 2 and html.escape(rows[0]["quantity"]) in page


@pytest.mark.parametrize("argv", [["reproduce", "--exercise", "no_such_exercise"],
                                  ["reproduce", "--exercise", "lqg_vs_pid", "--html", __file__]])
def test_reproduce_bad_input_exits_2_with_one_line(argv, capsys):
    assert main(argv) == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith("error:") and "\n" not in error


def test_reproduce_exits_1_when_a_claim_fails(monkeypatch, capsys):
    exercise = EXERCISES["lqg_vs_pid"]
    broken = exercise.claims[0].__class__(**{**exercise.claims[0].__dict__, "accept": (1e9, None)})
    monkeypatch.setattr(type(exercise), "claims", (broken,))
    assert main(["reproduce", "--quick", "--exercise", "lqg_vs_pid"]) == 1
    assert "FAIL" in capsys.readouterr().out
