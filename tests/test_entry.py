"""Typed values of number parameters (app/panels/entry.py; issue 11, defect 10): what a student may type,
what is refused and the one line that says so."""

from __future__ import annotations

import threading

import pytest

from app.panels import entry
from lab_modules.parameters import Parameter, ParameterError

NOISE = Parameter("noise", "Position sensor noise σ", "µm", 1.3323, 0.0, 10.0, "Sensor noise.")
SEED = Parameter("seed", "Random seed", "", 0, 0, 2**31 - 1, "Seed.", integer=True)


@pytest.mark.parametrize("text, number", [
    ("1.5", 1.5), ("1,5", 1.5), (" 1,5 ", 1.5), ("-1,5", -1.5), ("−1.5", -1.5), ("+2", 2.0),
    (",5", 0.5), ("5.", 5.0), ("15e-1", 1.5), ("1.5E3", 1500.0), ("1,5e-3", 0.0015),
    ("1 000", 1000.0), ("1\u202f000", 1000.0), ("1.5 µm", 1.5), ("1.5µm", 1.5), ("0", 0.0),
])
def test_numbers_a_student_types_are_read(text, number):
    assert entry.read_number(text, "µm") == pytest.approx(number, rel=1e-15)


@pytest.mark.parametrize("text, reason", [
    ("", "is empty"), ("   ", "is empty"), ("abc", "is not a number"), ("1.5 mm", "is not a number"),
    ("nan", "is not a number"), ("inf", "is not a number"), ("-Infinity", "is not a number"),
    ("1e999", "is too large"), ("1,000.5", "is ambiguous"), ("1,2,3", "is ambiguous"),
    ("1.2.3", "is not a number"), ("0x10", "is not a number"), ("1_000", "is not a number"),
    ("e5", "is not a number"), ("1e", "is not a number"), ("-", "is not a number"),
])
def test_what_is_not_a_number_is_refused_with_its_reason(text, reason):
    with pytest.raises(entry.EntryError, match=reason):
        entry.read_number(text, "µm")


def test_range_and_integers_are_checked():
    assert entry.read(NOISE, "10") == 10.0
    assert entry.read(SEED, "1e3") == 1000 and isinstance(entry.read(SEED, "1e3"), int)
    for parameter, text, reason in ((NOISE, "10,01", "is out of range"), (NOISE, "-0.1", "is out of range"),
                                    (SEED, "2.5", "is not a whole number"), (NOISE, "x", "is not a number")):
        with pytest.raises(ParameterError, match=reason):
            entry.read(parameter, text)


def test_the_refusal_is_one_line_naming_parameter_entry_range_and_value_in_use():
    line = entry.refusal(NOISE, "99", "is out of range", 1.3323)
    assert line == ("Position sensor noise σ: “99” is out of range; valid: 0 … 10 µm (0.5 or 0,5). "
                    "The lab keeps 1.3323 µm.")
    assert entry.refusal(NOISE, "", "is empty", 2.0).startswith("Position sensor noise σ: an empty entry changes")
    assert "\n" not in entry.refusal(NOISE, "a\nb" * 40, "is not a number", 1.0)
    assert entry.refusal(SEED, "x", "is not a number", 7).endswith("The lab keeps 7.")
    choice = Parameter("feedback", "Feedback source", "", "measured", choices=("measured", "estimated"))
    assert "valid: one of measured, estimated" in entry.refusal(choice, "x", "is not valid", "measured")


def test_shown_values_carry_no_float_noise():
    assert entry.shown_value(10 ** __import__("math").log10(0.0123)) == "0.0123"
    assert entry.shown_value(1.3320000000000001) == "1.332"
    assert entry.shown_value(3) == "3"
    assert entry.shown_value(1.352082207e-11) == "1.3521e-11"       # fits the box


def test_the_box_is_read_once_typing_stopped(monkeypatch):
    monkeypatch.setattr(entry, "QUIET_S", 0.05)
    monkeypatch.setattr(entry, "QUIET_EMPTY_S", 0.2)
    calls = []
    done = threading.Event()
    quiet = entry.Quiet(lambda: (calls.append(1), done.set()))
    for text in ("1", "12", "12,"):
        quiet.typed(text)
    assert done.wait(1.0) and calls == [1]               # one read for the burst
    done.clear()
    quiet.typed("")
    assert not done.wait(0.1)                             # an emptied box waits longer
    assert done.wait(1.0) and calls == [1, 1]
    done.clear()
    quiet.typed("3")
    quiet.cancel()
    assert not done.wait(0.2) and calls == [1, 1]


def test_another_control_takes_the_typed_value_first(monkeypatch):
    """A value typed and a button clicked at once: the click reads the box first (``Quiet.now``)."""
    monkeypatch.setattr(entry, "QUIET_S", 5.0)
    calls = []
    quiet = entry.Quiet(lambda: calls.append("read"))
    quiet.now()
    assert calls == []                                    # nothing typed: nothing to read
    quiet.typed("0,01")
    quiet.now()
    assert calls == ["read"]                              # at once, not 5 s later
    quiet.now()
    assert calls == ["read"]                              # and once
