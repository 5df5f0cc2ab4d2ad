"""Typed entries for the number parameters (issue 11, defect 10).

viser's number box keeps its own text in the browser: an emptied box or letters stay there unseen
by the server, and a decimal comma may be dropped. Each number parameter therefore gets a plain text
box beside its slider (in place of the slider's own number box, see ``STYLE``), read here on the
server once the student has stopped typing: "1,5", "1.5", " 1.5 µm", "15e-1" and "−1.5" are
numbers; an empty entry, letters, NaN or infinity and values outside the range are refused with one
line naming the parameter, what was typed and the valid range, and the box shows the value in use
again. Nothing here is shared between tabs: each tab's session owns its boxes and timers.
"""

from __future__ import annotations

import math
import re
import threading
from collections.abc import Callable

from lab_modules.parameters import Parameter, ParameterError

#: The student has stopped typing once the box is this still [s]; an emptied box waits longer,
#: it is usually emptied to type a new value.
QUIET_S = 1.0
QUIET_EMPTY_S = 2.5
MINUS_SIGNS = "−–‐"               # Unicode minus, en dash and hyphen typed or pasted for "-"
SPACES = " \u00a0\u2009\u202f"    # spaces, also the no-break and thin ones of pasted "1 000"

#: One style element for the page (``gui.add_html``): a slider followed by its entry box shares its
#: row with it (a two-column grid in the slider's folder), the slider's own number box is hidden, the
#: entry's empty label takes no room. Sliders without an entry are left alone.
STYLE = """<style>
div:has(> div > .mantine-Flex-root > div > p > label:empty) {
  display: grid; grid-template-columns: minmax(0, 1fr) 5.25rem; align-items: center; }
div:has(> div > .mantine-Flex-root > div > p > label:empty) > * { grid-column: 1 / -1; }
div:has(> div > .mantine-Flex-root > div > p > label:empty) > div:has(+ div > .mantine-Flex-root > div > p > label:empty) {
  grid-column: 1; }
div:has(> .mantine-Flex-root > div > p > label:empty) { grid-column: 2 !important; padding-left: 0 !important; }
div:has(> .mantine-Flex-root > div > p > label:empty) input { padding: 0 0.3em !important; letter-spacing: -0.5px; }
div:has(> .mantine-Flex-root > div > p > label:empty) > .mantine-Flex-root > div:has(> p > label:empty) {
  display: none; }
div:has(+ div > .mantine-Flex-root > div > p > label:empty) .mantine-Slider-root + .mantine-NumberInput-root {
  display: none; }
</style>"""


class EntryError(ValueError):
    """Why a typed text is not a number (a few words, e.g. "is not a number")."""


def read_number(text: str, unit: str = "") -> float:
    """The number in a typed ``text``: a decimal comma ("1,5") counts as a point, spaces (also
    between digit groups) and a trailing ``unit`` are ignored, Unicode minus signs are minus signs,
    exponents ("2e-3", "2E3") are taken. Raises EntryError for an empty text, letters, a comma
    and a point together ("1,000.5" is ambiguous), digits other than 0-9 (full-width, Arabic-Indic:
    the point or comma beside them would not be read either), NaN and infinity."""
    cleaned = str(text).strip()
    if unit and cleaned.endswith(unit):
        cleaned = cleaned[: -len(unit)]
    for space in SPACES:
        cleaned = cleaned.replace(space, "")
    for minus in MINUS_SIGNS:
        cleaned = cleaned.replace(minus, "-")
    if not cleaned:
        raise EntryError("is empty")
    if "," in cleaned:
        if "." in cleaned or cleaned.count(",") > 1:
            raise EntryError("is ambiguous (use one decimal point or one decimal comma)")
        cleaned = cleaned.replace(",", ".")
    if not re.fullmatch(r"[+-]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?", cleaned):
        raise EntryError("is not a number")
    number = float(cleaned)
    if not math.isfinite(number):
        raise EntryError("is too large")
    return number


def read(parameter: Parameter, text: str) -> float | int:
    """The value a typed ``text`` sets ``parameter`` to; raises ParameterError with the message
    the tab shows (``refusal``) when it sets nothing."""
    try:
        number = read_number(text, parameter.unit)
    except EntryError as error:
        raise ParameterError(str(error)) from None
    if not parameter.minimum <= number <= parameter.maximum:
        raise ParameterError("is out of range")
    if parameter.integer and number != int(number):
        raise ParameterError("is not a whole number")
    return int(number) if parameter.integer else number


def valid_range(parameter: Parameter) -> str:
    if parameter.choices:
        return parameter.valid_range()
    unit = f" {parameter.unit}" if parameter.unit else ""
    return f"{parameter.minimum:.10g} … {parameter.maximum:.10g}{unit}"


def refusal(parameter: Parameter, text: str, reason: str, in_use) -> str:
    """The one line (plain text, to be escaped for Markdown) a tab shows for a refused entry."""
    unit = f" {parameter.unit}" if parameter.unit else ""
    typed = " ".join(str(text).split())[:40]
    what = f"“{typed}” {reason}" if typed else "an empty entry changes nothing"
    return (f"{parameter.label}: {what}; valid: {valid_range(parameter)} (0.5 or 0,5). "
            f"The lab keeps {shown_value(in_use)}{unit}.")


def shown_value(value) -> str:
    """A value as its box shows it: as typed where that fits the box (up to 9 characters, no float
    noise), else to five significant digits ("1.3521e-11")."""
    if isinstance(value, (int, str)):
        return str(value)
    text = f"{float(value):.10g}"
    return text if len(text) <= 9 else f"{float(value):.5g}"


class Quiet:
    """Calls ``action`` once its box has been still for ``QUIET_S`` (``QUIET_EMPTY_S`` when it is
    empty); every keystroke restarts the wait. ``cancel`` drops a pending call."""

    def __init__(self, action: Callable[[], None]):
        self.action = action
        self.timer: threading.Timer | None = None
        self.lock = threading.Lock()

    def typed(self, text: str) -> None:
        with self.lock:
            if self.timer is not None:
                self.timer.cancel()
            self.timer = threading.Timer(QUIET_EMPTY_S if not str(text).strip() else QUIET_S, self.action)
            self.timer.daemon = True
            self.timer.start()

    def cancel(self) -> None:
        with self.lock:
            if self.timer is not None:
                self.timer.cancel()
                self.timer = None

    def now(self) -> None:
        """Call a pending ``action`` at once: the student left the box for another control
        (viser reports no blur), so a value typed and a button clicked right after are taken in order."""
        with self.lock:
            pending, self.timer = self.timer, None
        if pending is not None:
            pending.cancel()
            self.action()


def add_box(gui, parameter: Parameter, value, label: str, on_still: Callable[[object], None], hint: str | None):
    """A text box showing ``value``, and its ``Quiet`` wait; ``on_still(box)`` runs (on a timer thread: it should only queue
    work) once the student stopped typing in it. ``label`` "" puts it beside the slider added just
    before it (``STYLE``). Assignments from the server (the value in use shown again) are not typing."""
    box = gui.add_text(label, shown_value(value), hint=hint)
    quiet = Quiet(lambda: on_still(box))

    async def on_update(event) -> None:
        if event.client is not None:              # typed in the browser, not set by the lab
            quiet.typed(box.value)
    box.on_update(on_update)
    return box, quiet


def show(box, value) -> None:
    """Let ``box`` show ``value`` (the value in use) unless it shows it already."""
    if box is not None:
        text = shown_value(value)
        if box.value != text:
            box.value = text
