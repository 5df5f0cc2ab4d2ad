"""Paper claims as data.

Each exercise declares the headline results of its source paper as ``Claim``
objects: what the paper reports, which of the exercise's headless metrics
measures it, and the range the lab holds itself to.  The claims test, the
worksheets' "paper vs lab" tables and ``python -m app reproduce`` all read
the same objects, so no lab number is typed twice.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field


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
        """The accepted range as text, e.g. ``">= 75 %"`` or ``"2.9 ... 3.3 N/µm"``."""
        low, high = self.accept
        if low is not None and high is not None:
            return f"{low:g} … {high:g} {self.unit}".strip()
        if low is not None:
            return f"≥ {low:g} {self.unit}".strip()
        return f"≤ {high:g} {self.unit}".strip()
