"""Numbers as a student reads them, written one way everywhere: readouts, action results,
the filter inspector, the pole table, the worksheets' claims tables and
``python -m app reproduce``.

* a number: ``digits`` significant digits (3 unless a place asks for more), thousands
  grouped from 1 000 up to 10⁹ with at least 4 digits ("480 000", "1 319"), powers of
  ten written out beyond and below 10⁻⁴ ("7.5·10⁻⁸");
* an integer (a count): every digit, grouped ("12 345");
* NaN (no value): "—"; not computed yet (``None``): "…"; infinities: "∞", "-∞";
* a word instead of a number ("touched down"): as it is.

A value shown next to an accepted range gets the digits that place it inside or outside
the range as the exact value lies (``range_digits``): "10.05 N/A" in "10.04 … 10.06", not
"10.1".
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

PENDING = "…"                     # not computed yet
NOT_A_NUMBER = "—"                # NaN
INFINITY = "∞"
MINUS_INFINITY = "-∞"             # the minus of every negative number shown
GROUP_SEPARATOR = "\u202f"        # narrow no-break space: "480 000" never breaks across lines
GROUPED_FROM, GROUPED_BELOW = 1e3, 1e9
GROUPED_MIN_DIGITS = 4            # 1 000 ... 9 999 keep every digit ("1 319", not "1 320")
SMALLEST_PLAIN = 1e-4             # below: a power of ten ("3·10⁻⁵", not "0.00003")
DIGITS = 3
RANGE_END_DIGITS = 10             # a range end as the code writes it (31.4628534, not 31.4629)
MAX_DIGITS = 17                   # every double is told apart from its neighbours at 17 digits
SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def _grouped(number: float) -> bool:
    return GROUPED_FROM <= abs(number) < GROUPED_BELOW


def rounded(value: float, digits: int = DIGITS) -> float:
    """``value`` as ``number(value, digits)`` shows it: ``digits`` significant digits, at least
    ``GROUPED_MIN_DIGITS`` where thousands are grouped."""
    shown = float(f"{value:.{digits}g}")
    if _grouped(shown) and digits < GROUPED_MIN_DIGITS:
        shown = float(f"{value:.{GROUPED_MIN_DIGITS}g}")
    return shown


def number(value: float | str | None, digits: int = DIGITS) -> str:
    """``value`` as a student reads it (the rules in the module's docstring); ``digits`` ≥ 3."""
    if isinstance(value, str):                            # a word instead of a number
        return value
    if value is None:
        return PENDING
    if isinstance(value, (int, np.integer)):              # a count
        return f"{int(value):,}".replace(",", GROUP_SEPARATOR)
    value = float(value)
    if math.isnan(value):
        return NOT_A_NUMBER
    if math.isinf(value):
        return INFINITY if value > 0 else MINUS_INFINITY
    shown = rounded(value, digits) + 0.0           # + 0.0: no "-0" for a value that rounds to zero
    if _grouped(shown):
        integer_digits = len(str(int(abs(shown))))
        text = f"{shown:,.{max(0, max(digits, GROUPED_MIN_DIGITS) - integer_digits)}f}"
        text = text.rstrip("0").rstrip(".") if "." in text else text
        return text.replace(",", GROUP_SEPARATOR)
    if shown != 0 and not SMALLEST_PLAIN <= abs(shown) < GROUPED_BELOW:
        mantissa, exponent = f"{shown:.{digits - 1}e}".split("e")
        mantissa = mantissa.rstrip("0").rstrip(".") if "." in mantissa else mantissa
        return f"{mantissa}·10{str(int(exponent)).translate(SUPERSCRIPT)}"
    return f"{shown:.{digits}g}"


def signed(value: float, decimals: int = 2) -> str:
    """A ratio in a column of ratios: its sign and ``decimals`` fixed decimals ("+0.93", "-1.20");
    NaN and infinities as ``number`` shows them."""
    return f"{value:+.{decimals}f}" if math.isfinite(value) else number(value)


def _side(value: float, end: float) -> int:
    """+1 above ``end``, −1 below, 0 on it."""
    return (value > end) - (value < end)


def range_digits(value: float, ends: Iterable[float]) -> int:
    """The fewest significant digits, at least ``DIGITS``, at which ``value`` as ``number``
    shows it lies on the same side of every range end as ``value`` itself, each end as
    ``number(end, RANGE_END_DIGITS)`` shows it: never on an end it is not equal to, never
    across one.  A value within an end's own rounding (10⁻¹⁰ relative) of it gets every digit."""
    ends = [(end, rounded(end, RANGE_END_DIGITS)) for end in ends]
    if not math.isfinite(value):
        return DIGITS
    for digits in range(DIGITS, MAX_DIGITS + 1):
        shown = rounded(value, digits)
        if all(_side(shown, shown_end) == _side(value, end) for end, shown_end in ends):
            return digits
    return MAX_DIGITS
