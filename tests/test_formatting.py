"""The lab's one number format (``lab_modules/formatting.py``) and its readers: readouts,
action results, the filter inspector, the pole table, the claims tables and ``reproduce``.

A claim's value is shown with the digits that place it inside or outside its accepted
range as the verdict does: checked on every claim of every exercise with values at and
around its range ends, and on the values two exercises measure."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.commands.reproduce import lab_text
from app.panels import actions, inspector, pole_map, text
from lab_modules.claims import Claim, format_value, markdown_table
from lab_modules.evaluation.measured_claims import Row, measure
from lab_modules.exercises import Analysis, get, registry
from lab_modules.formatting import (
    MAX_DIGITS,
    NOT_A_NUMBER,
    PENDING,
    number,
    range_digits,
    rounded,
    signed,
)
from tests.page_reading import shown_number

NNBSP = "\u202f"                 # the narrow no-break space that groups thousands


# -- the rules ------------------------------------------------------------------------------------
def test_no_value_not_yet_and_infinities_each_have_one_sign():
    assert number(float("nan")) == number(np.float32("nan")) == NOT_A_NUMBER == "—"
    assert number(None) == PENDING == "…"
    assert number(float("inf")) == "∞" and number(-np.inf) == "-∞"
    assert signed(float("nan")) == "—" and signed(float("inf")) == "∞"


def test_words_stay_words():
    assert number("touched down") == "touched down" and number("computing …", 4) == "computing …"


def test_three_significant_digits_unless_a_place_asks_for_more():
    assert number(0.123456) == "0.123" and number(0.123456, 4) == "0.1235" and number(1.0043, 4) == "1.004"
    assert number(240.0) == "240" and number(0.6) == "0.6" and number(-3.0) == "-3"
    assert number(0.0) == "0" and number(-0.0) == "0" and number(-1e-30) == "-1·10⁻³⁰"


def test_thousands_are_grouped_with_at_least_four_digits():
    assert number(480_000.0) == f"480{NNBSP}000" and number(1.03e6) == f"1{NNBSP}030{NNBSP}000"
    assert number(-1700.0) == f"-1{NNBSP}700" and number(1318.8) == f"1{NNBSP}319"
    assert number(12345.0) == f"12{NNBSP}340" and number(1234.5, 5) == f"1{NNBSP}234.5"
    assert number(999.96) == f"1{NNBSP}000"                  # rounds into the grouped band
    assert number(999.4) == "999"


def test_counts_keep_every_digit():
    assert number(12345) == f"12{NNBSP}345" and number(np.int64(5000)) == f"5{NNBSP}000" and number(25) == "25"


def test_powers_of_ten_beyond_the_grouped_band_and_below_a_ten_thousandth():
    assert number(7.5e-8) == "7.5·10⁻⁸" and number(3e-5) == "3·10⁻⁵" and number(1.339e-5) == "1.34·10⁻⁵"
    assert number(1e-4) == "0.0001" and number(1.2345e-4) == "0.000123"
    assert number(1.234e9) == "1.23·10⁹" and number(9.9996e8) == "1·10⁹" and number(2.5e12, 4) == "2.5·10¹²"


def test_rounded_is_the_number_shown():
    for value in (0.123456, 1318.8, 999.96, 7.5e-8, 480_000.0000002452, -2132.9207):
        for digits in (3, 4, 6, 10):
            assert shown_number(number(value, digits)) == pytest.approx(rounded(value, digits), rel=1e-15)


# -- digits that place a value against its range ----------------------------------------------
def test_the_issues_example_reads_inside_its_range():
    """Was "10.1 N/A, accepted 10.04 … 10.06, pass"."""
    claim = Claim("s", "stiffness", "10.05", "k", (10.04, 10.06), "N/A")
    value = 10.050502520938217
    assert range_digits(value, claim.accept) == 4 and format_value(value, claim.accept) == "10.05"
    assert "| 10.05 N/A | 10.04 … 10.06 N/A | pass |" in markdown_table((claim,), [value])


@pytest.mark.parametrize("value, accept, shown", [
    (10.0644, (9.95, 10.15), "10.1"),                  # three digits are enough
    (10.0601, (10.04, 10.06), "10.1"),                 # outside stays outside
    (10.0399, (10.04, 10.06), "10"),
    (10.04001, (10.04, 10.06), "10.04001"),            # inside, but not on the end
    (10.0595, (10.04, 10.06), "10.059"),               # 4 digits read "10.06": on the end
    (10.06, (10.04, 10.06), "10.06"),                  # on the end: the end itself
    (25.0, (25, 25), "25"),
    (0.9524207621813019, (0.952281, 0.952481), "0.9524"),
    (1.0500398038619574, (1.0499, 1.0501), "1.05"),
    (480_000.0000002452, (479_520.0, 480_479.99999999994), f"480{NNBSP}000"),
    (18_800.000000006257, (18_781.2, 18_818.8), f"18{NNBSP}800"),
    (-1318.808336158503, (-1344.36, -1291.64), f"-1{NNBSP}319"),
    (4.325208720401541e-05, (0.0, 0.0002), "4.33·10⁻⁵"),
    (80.0001, (80, None), "80.0001"),                  # one open side
    (4.99999, (None, 5), "4.99999"),
    (float("nan"), (1, 2), "—"),
])
def test_range_digits_edges(value, accept, shown):
    assert format_value(value, accept) == shown


def test_a_value_within_an_ends_own_rounding_gets_every_digit():
    """Range ends are shown to 10 significant digits: a value between an end and its shown
    rounding cannot be placed by its own digits (the verdict's exact end is not shown)."""
    end = 1.00000000001                                       # shown "1"
    assert range_digits(1.000000000005, (end,)) == MAX_DIGITS


def test_a_value_not_yet_measured_and_a_failed_measurement():
    claim = Claim("s", "q", "1", "m", (1.0, 2.0), "mH")
    table = markdown_table((claim,), [None])
    assert "| … | 1 … 2 mH | … |" in table
    assert "| — | 1 … 2 mH | FAIL |" in markdown_table((claim,), [float("nan")])
    assert lab_text(Row("x", claim)) == "—"


def test_reproduce_shows_the_range_over_seeds_with_placing_digits():
    claim = Claim("s", "q", "1", "m", (10.04, 10.06), "N/A")
    row = Row("x", claim, [10.0505, 10.0401, 10.0599])
    assert lab_text(row) == "10.05 N/A (10.0401 … 10.0599)"


# -- every claim of every exercise: the shown value against the shown range agrees with the verdict
def shown_range(claim: Claim) -> tuple[float | None, float | None]:
    """The accepted range as a reader takes it from ``accept_text``: "= a", "a … b", "≥ a", "≤ b"."""
    words = claim.accept_text().split(" ")
    if words[0] == "=":
        return shown_number(words[1]), shown_number(words[1])
    if words[0] == "≥":
        return shown_number(words[1]), None
    if words[0] == "≤":
        return None, shown_number(words[1])
    return shown_number(words[0]), shown_number(words[2])


def check_shown_agrees(claim: Claim, value: float) -> None:
    """A reader comparing the shown value with the shown ends finds the verdict, and finds the
    value on an end only where it is exactly there."""
    shown = shown_number(format_value(value, claim.accept))
    low, high = shown_range(claim)
    inside = not math.isnan(shown) and (low is None or shown >= low) and (high is None or shown <= high)
    assert inside == claim.holds(value), (claim.quantity, value, format_value(value, claim.accept),
                                          claim.accept_text())
    for end, shown_end in zip(claim.accept, (low, high)):
        if end is not None and value != end:
            assert shown != shown_end, (claim.quantity, value, format_value(value, claim.accept))


def near_the_ends(claim: Claim) -> list[float]:
    """Values at, just inside and just outside each end (relative steps of 10⁻¹ ... 10⁻⁹ of the
    range's scale, and the halfway points where rounding to 3 ... 8 digits flips), and inside."""
    ends = [end for end in claim.accept if end is not None]
    scale = max(abs(ends[-1] - ends[0]), *(abs(e) for e in ends)) or 1.0
    values = [sum(ends) / len(ends)]
    for end in ends:
        values += [end + sign * scale * 10.0 ** -k for sign in (-1, 1) for k in range(1, 10)]
        exponent = math.floor(math.log10(abs(end))) if end else 0
        values += [end + sign * 0.5 * 10.0 ** (exponent - digits + 1) for sign in (-1, 1) for digits in range(3, 9)]
        values.append(end)
    return values


CLAIMS = [(name, claim) for name, exercise in registry().items() for claim in exercise.claims]


@pytest.mark.parametrize("name, claim", CLAIMS, ids=[f"{name}-{claim.metric}" for name, claim in CLAIMS])
def test_every_claim_shows_values_near_its_ends_as_its_verdict_says(name, claim):
    for value in near_the_ends(claim):
        check_shown_agrees(claim, value)


@pytest.fixture(scope="module")
def measured_rows():
    """What ``reproduce --quick --json`` measures for two exercises: one with the issue's example
    (stiffness_map) and one with grouped thousands and narrow ranges (maglev_tracking)."""
    return measure([get("stiffness_map"), get("maglev_tracking")], quick=True)


def test_measured_values_show_as_their_verdict_says(measured_rows):
    assert len(measured_rows) == len(get("stiffness_map").claims) + len(get("maglev_tracking").claims)
    for row in measured_rows:
        assert row.value is not None, row.error
        check_shown_agrees(row.claim, row.value)
    shown = {row.claim.metric: lab_text(row) for row in measured_rows}
    assert "10.05 N/A" in shown.values()                      # the issue's row, no longer "10.1 N/A"


# -- the readers use it -----------------------------------------------------------------------------
def test_readouts_action_results_inspector_and_pole_table_share_the_format():
    assert text.readout is number
    result = actions.result_markdown(Analysis([("periods", 5000, ""), ("ratio", float("nan"), ""),
                                               ("std", 1.0043, "µH")], {}, []), running=False)
    assert f"| periods | 5{NNBSP}000 |" in result and "| ratio | — |" in result and "| std | 1.004 | µH |" in result
    table = pole_map.table_markdown({"closed loop": np.array([-3 + 4j, -3 - 4j, -0.4, -2e4 + 9e3j, -2e4 - 9e3j])})
    assert "| -0.4 |" in table and f"-20{NNBSP}000 ± 9{NNBSP}000j" in table and f"| 3{NNBSP}491 |" in table
    state = {"x": [1e-6, 2.0], "P": [[1e-14, 0.0], [0.0, 0.0]], "time_s": 0.01, "title": "filter",
             "states": [("position x", "m"), ("force F", "")], "K": None}
    shown = inspector.markdown(state, 1e-4)
    assert "| position x | 1 | 0.1 | µm |" in shown and "| force F | 2 | 0 |  |" in shown and "| F | — | — |" in shown
