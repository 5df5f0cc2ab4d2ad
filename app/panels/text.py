"""Text a student reads in a tab: readout values, table cells and typed text shown as typed."""

from __future__ import annotations

import re

from lab_modules.formatting import number

#: A readout's value as a student reads it (3 significant digits, thousands grouped up to 10⁹,
#: powers of ten beyond, "—" for NaN, a word as it is): the lab's one number format.
readout = number


def escaped(text) -> str:
    """Text shown in a Markdown element as typed (file names, error messages): Markdown's
    special characters backslash-escaped, then &, < and > as HTML entities (viser's
    Markdown renders raw HTML)."""
    text = re.sub(r"([\\`*_{}\[\]()#+\-.!|~])", r"\\\1", str(text))
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def cell(text: str) -> str:
    """A readout's label or unit as one Markdown table cell: "|S|max" must not end the cell."""
    return str(text).replace("|", "\\|")


LIVE_SUFFIX = " (scope window)"   # marks the readouts an exercise computes from the scope window


def readout_rows(result, exercise, trace: dict) -> list[tuple[str, object, str]]:
    """The readouts a tab shows: the analysis's (``result`` may be None), then the exercise's
    figures of the scope window ``trace`` (column -> samples) once it holds 10 samples."""
    rows = list(result.readouts) if result is not None else []
    if len(next(iter(trace.values()), ())) >= 10:
        rows += [(f"{label}{LIVE_SUFFIX}", value, unit) for label, value, unit in exercise.live_readouts(trace)]
    return rows
