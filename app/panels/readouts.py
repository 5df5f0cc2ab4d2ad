"""The readouts of the Scope tab (issue 25): the key readouts a worksheet's tasks name, pinned
above the charts where a 1366 x 768 screen shows them without scrolling, and every readout below
the charts, a long list grouped by what it is about and folded (HTML ``details``, which viser's
Markdown renders; a group the student opens stays open while its values change)."""

from __future__ import annotations

import html

from app.panels.text import LIVE_SUFFIX, cell, readout

LONG_LIST_ROWS = 20               # a longer list is grouped, its groups folded
KEY_HEADER = ("| key readout | value | unit |", "|---|---:|---|")
HEADER = ("| quantity | value | unit |", "|---|---:|---|")
LIVE_GROUP = "This run (scope window)"
#: Why a key readout has no value yet: a scope-window figure needs 10 samples of the run, and a
#: figure of the Analysis tab is computed while that tab is shown (issue 23), for the values then.
ABSENT_NOTE = "measured once the run has begun, or (a sweep) while the Analysis tab is shown"


#: Joins a unit's characters where the browser would break a line ("N/" above "µm" in a narrow unit
#: column, the label beside it taking the width): U+2060 WORD JOINER, invisible.
WORD_JOINER = "\u2060"


def unit_cell(unit: str) -> str:
    """A unit as one unbreakable table cell ("N/µm", "1/(m·s)²" stay on one line)."""
    return cell(unit).replace("/", "/" + WORD_JOINER)


def row_markdown(label: str, value, unit: str) -> str:
    """One table row; a word in place of a number ("touched down") carries no unit."""
    return f"| {cell(label)} | {readout(value)} | {'' if isinstance(value, str) else unit_cell(unit)} |"


def key_rows(rows, keys: tuple[str, ...], absent: str | None = None) -> list:
    """The rows named in ``keys`` (an analysis readout's label, or a scope-window readout's without
    its suffix), in the order of ``keys``; a key without a row yet is left out, or with ``absent``
    shows that word."""
    by_label = {label: (label, value, unit) for label, value, unit in rows}
    found = (by_label.get(key) or by_label.get(key + LIVE_SUFFIX) or (absent and (key, absent, "")) for key in keys)
    return [row for row in found if row]


def pinned_markdown(rows, keys: tuple[str, ...], absent: str | None = None) -> str:
    """The key readouts as a small table ("" when the exercise names none); with ``absent``, a key
    without a row shows that word and a note below the table says when it comes (``ABSENT_NOTE``)."""
    pinned = key_rows(rows, keys, absent)
    if not pinned:
        return ""
    note = [f"\n*{absent}: {ABSENT_NOTE}*"] if any(value == absent for _, value, _ in pinned) else []
    return "\n".join([*KEY_HEADER, *(row_markdown(*row) for row in pinned), *note])


def group_of(label: str) -> str | None:
    """What a readout is about: the scope window, or the part before ": " ("PID: overshoot …")."""
    if label.endswith(LIVE_SUFFIX):
        return LIVE_GROUP
    prefix, colon, _ = label.partition(": ")
    return prefix if colon else None


def table(rows) -> str:
    return "\n".join([*HEADER, *(row_markdown(*row) for row in rows)])


def sections(rows) -> tuple[list, dict[str, list]]:
    """The list under the charts as it is shown: the rows in view (all of a short list; in a long
    one those about no group), and the groups of two or more rows, by name, in their order."""
    if len(rows) <= LONG_LIST_ROWS:
        return list(rows), {}
    groups: dict[str | None, list] = {}
    for row in rows:
        groups.setdefault(group_of(row[0]), []).append(row)
    grouped = {name: members for name, members in groups.items() if name is not None and len(members) >= 2}
    return [row for row in rows if group_of(row[0]) not in grouped], grouped


def grouped_markdown(rows, notes=()) -> str:
    """Every readout under the charts, then the notes in italics: one table, or for a long list the
    rows about no group first, then a folded section per group of two or more rows (the scope
    window's open: it follows the run)."""
    loose, groups = sections(rows)
    parts = [table(loose)] if loose else []
    for name, members in groups.items():
        opened = " open" if name == LIVE_GROUP else ""
        parts.append(f"<details{opened}><summary><b>{html.escape(name)}</b> ({len(members)} readouts)"
                     "</summary>\n\n"
                     f"{table(members)}\n\n</details>")
    parts += [f"*{note}*" for note in notes]
    return '<div class="lab-readouts">\n\n' + "\n\n".join(parts) + "\n\n</div>"
