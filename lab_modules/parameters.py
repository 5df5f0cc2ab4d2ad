"""Exercise parameters: name, unit, default, range, and validation.

A bad value never reaches the physics: ``resolve`` raises ``ParameterError``
with one line that names the parameter and its valid range.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


class ParameterError(ValueError):
    """A parameter name or value is not acceptable (one-line message)."""


@dataclass(frozen=True)
class Parameter:
    """One control of an exercise.

    ``choices`` makes it a choice among strings; otherwise it is a number in
    [minimum, maximum].  ``log`` asks the browser for a logarithmic slider.
    """

    name: str
    label: str
    unit: str
    default: float | str
    minimum: float | None = None
    maximum: float | None = None
    description: str = ""
    choices: tuple[str, ...] = ()
    log: bool = False
    step: float | None = None
    integer: bool = False
    group: str = "Settings"

    def valid_range(self) -> str:
        if self.choices:
            return "one of " + ", ".join(self.choices)
        unit = f" {self.unit}" if self.unit else ""
        return f"{self.minimum:.10g} ... {self.maximum:.10g}{unit}"

    def parse(self, value) -> float | str:
        """Check one value (number or text) and return it in the parameter's type.  A number
        written as text takes the digits 0-9 only: Python would also read other scripts' digits
        ("١٠", "１０") and digit groups with underscores ("1_0") as numbers, which a lab reading
        a student's or a script's input should refuse rather than guess."""
        if self.choices:
            text = str(value).strip()
            if text not in self.choices:
                raise ParameterError(f"{self.name}={value!r} is not valid: expected {self.valid_range()}")
            return text
        if isinstance(value, str) and (not value.isascii() or "_" in value):
            raise ParameterError(f"{self.name}={value!r} is not a number (digits 0-9 only): "
                                 f"expected {self.valid_range()}")
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise ParameterError(
                f"{self.name}={value!r} is not a number: expected {self.valid_range()}") from None
        if not math.isfinite(number):
            raise ParameterError(f"{self.name}={value!r} is not finite: expected {self.valid_range()}")
        if not self.minimum <= number <= self.maximum:
            raise ParameterError(f"{self.name}={value!r} is out of range: expected {self.valid_range()}")
        if self.integer:
            if number != int(number):
                raise ParameterError(f"{self.name}={value!r} is not an integer: expected {self.valid_range()}")
            return int(number)
        return number

    def describe(self) -> dict:
        """JSON description for ``python -m app list --json``."""
        entry = {"name": self.name, "label": self.label, "unit": self.unit,
                 "default": self.default, "description": self.description}
        if self.choices:
            entry["choices"] = list(self.choices)
        else:
            entry.update(min=self.minimum, max=self.maximum, log=self.log)
        return entry


def resolve(parameters: tuple[Parameter, ...], overrides: dict | None = None) -> dict:
    """Defaults updated by ``overrides`` (name -> value), every value checked."""
    by_name = {p.name: p for p in parameters}
    values = {p.name: p.default for p in parameters}
    for name, value in (overrides or {}).items():
        if name not in by_name:
            raise ParameterError(f"unknown parameter {name!r}: expected one of {', '.join(by_name)}")
        values[name] = by_name[name].parse(value)
    return values
