"""Paper claims as data.

Each exercise declares the headline results of its source paper as ``Claim``
objects: what the paper reports, which of the exercise's headless metrics
measures it, and the range the lab holds itself to.  The claims test, the
worksheets' "paper vs lab" tables and ``python -m app reproduce`` all read
the same objects, so no lab number is typed twice.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

from lab_modules.formatting import PENDING, RANGE_END_DIGITS, number, range_digits


@dataclass(frozen=True)
class Claim:
    """One paper-vs-lab comparison.

    Attributes
    ----------
    source : str
        Where the paper says it, e.g. ``"paper 000 §II, Fig. 3"``.
    quantity : str
        What is compared, e.g. ``"fed-back position RMS reduction"``.
    paper : str
        The paper's figure as printed, e.g. ``"about 80 %"``.
    metric : str
        Key of the exercise's ``metrics`` result; dots index nested
        dictionaries and lists (``"poles.0"``).
    accept : tuple
        (low, high) the lab's value must lie in; ``None`` leaves a side open.
    unit : str
        Unit of the metric, e.g. ``"%"``, ``"N/µm"``.
    note : str
        How it is measured, or, for a deviation, the reason in one sentence.
    deviation : bool
        True where the lab deliberately differs from the paper; ``accept`` is
        then the lab's own (documented) value, still checked.
    settings : dict
        Parameter overrides the metric is measured at (exercise defaults otherwise).
    duration_s : float or None
        Simulated time of the run (the exercise's default when None).
    """

    source: str
    quantity: str
    paper: str
    metric: str
    accept: tuple[float | None, float | None]
    unit: str
    note: str = ""
    deviation: bool = False
    settings: dict = field(default_factory=dict)
    duration_s: float | None = None

    def value_in(self, metrics: dict) -> float:
        """The claim's metric picked out of a ``metrics`` result."""
        value = metrics
        for key in self.metric.split("."):
            value = value[int(key)] if isinstance(value, (list, tuple)) else value[key]
        return float(value)

    def holds(self, value: float) -> bool:
        """Whether ``value`` lies in the accepted range (NaN never does)."""
        low, high = self.accept
        if math.isnan(value):
            return False
        return (low is None or value >= low) and (high is None or value <= high)

    def accept_text(self) -> str:
        """The accepted range as text, e.g. ``"≥ 75 %"`` or ``"2.945 … 3.255 N/µm"``: each end as
        the code writes it (``lab_modules.formatting.RANGE_END_DIGITS``)."""
        low, high = (end if end is None else number(end, RANGE_END_DIGITS) for end in self.accept)
        if low is not None and self.accept[0] == self.accept[1]:
            return f"= {low} {self.unit}".strip()
        if low is not None and high is not None:
            return f"{low} … {high} {self.unit}".strip()
        if low is not None:
            return f"≥ {low} {self.unit}".strip()
        return f"≤ {high} {self.unit}".strip()

    def value_text(self, value: float | None) -> str:
        """The lab's ``value`` with the claim's unit, with the digits that place it inside or
        outside the accepted range as ``holds`` does ("10.05 N/A" beside "10.04 … 10.06 N/A");
        ``…`` while not yet measured, "—" (no unit) for NaN."""
        text = format_value(value, self.accept)
        return f"{text} {self.unit}" if self.unit and value is not None and not math.isnan(value) else text


#: The line in a worksheet where the paper-vs-lab table is rendered.
WORKSHEET_MARKER = "<!-- claims -->"


def format_value(value: float | None, accept: tuple[float | None, float | None] = (None, None)) -> str:
    """A lab value for a table as ``lab_modules.formatting.number`` writes it (``…`` while not yet
    measured), with the significant digits (at least 3) that place it inside or outside
    ``accept`` as ``Claim.holds`` does (``formatting.range_digits``)."""
    if value is None:
        return PENDING
    return number(value, range_digits(value, [end for end in accept if end is not None]))


def status(claim: Claim, value: float | None) -> str:
    """``pass``, ``deviation (holds)``, ``FAIL`` (or ``…`` while not yet measured)."""
    if value is None:
        return PENDING
    if not claim.holds(value):
        return "FAIL"
    return "deviation (holds)" if claim.deviation else "pass"


def _plain(text: str) -> str:
    """Plain text in Markdown: identifiers such as ``gain_factor`` must not italicise."""
    return re.sub(r"([\\`*_$])", r"\\\1", text)


def _cell(text: str) -> str:
    return _plain(text).replace("|", "\\|").replace("\n", " ")


def markdown_table(claims: tuple[Claim, ...], values: list[float | None] | None = None,
                   parameters: tuple = ()) -> str:
    """The paper-vs-lab table of a worksheet: one row per claim with the lab's
    value (``…`` where ``values`` is None or has None: still being measured),
    then the claims' notes (how it is measured; a deviation's reason) as a list.
    A claim's settings are named as the controls label them (``parameters``)."""
    values = values if values is not None else [None] * len(claims)
    rows = ["| source | claim | paper | lab | accepted | status |", "|---|---|---|---|---|---|"]
    for claim, value in zip(claims, values):
        quantity = claim.quantity + (f" (with {settings_text(claim.settings, parameters)})" if claim.settings else "")
        rows.append("| " + " | ".join(_cell(text) for text in (
            claim.source, quantity, claim.paper, claim.value_text(value), claim.accept_text(),
            status(claim, value))) + " |")
    notes = [f"- *{_plain(claim.quantity)}*{' (deviation)' if claim.deviation else ''}: {_plain(claim.note)}"
             for claim in claims if claim.note]
    return "\n".join(rows + ([""] + notes if notes else []))


def settings_text(settings: dict, parameters: tuple = ()) -> str:
    """Parameter overrides as ``name = value, ...``; a parameter among ``parameters`` (``Parameter``)
    as its control is labelled, with its unit ("Current noise σ(i) = 0 mA")."""
    labelled = {parameter.name: parameter for parameter in parameters}

    def one(name: str, value) -> str:
        parameter = labelled.get(name)
        if parameter is None:
            return f"{name} = {value}"
        if isinstance(value, (str, bool)):                  # a choice or a switch: no unit
            return f"{parameter.label} = {value}"
        unit = f" {parameter.unit}" if parameter.unit else ""
        return f"{parameter.label} = {number(value, RANGE_END_DIGITS)}{unit}"
    return ", ".join(one(name, value) for name, value in settings.items())


def render_worksheet(text: str, table: str) -> str:
    """The worksheet with its marker line replaced by ``table``."""
    return "\n".join(table if line.strip() == WORKSHEET_MARKER else line for line in text.split("\n"))
