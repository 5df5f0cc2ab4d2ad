"""Exercise parameters: name, unit, default, range, validation and SI value.

A bad value never reaches the physics: ``resolve`` raises ``ParameterError``
with one line that names the parameter and its valid range.  A control shown in
µs, mm or mA is converted to SI once, where the physics reads it: ``in_si``.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from functools import cache, cached_property


class ParameterError(ValueError):
    """A parameter name or value is not acceptable (one-line message)."""


#: SI value = shown value × factor, for each scaled unit the lab's controls use.  Every control's
#: unit is here, already SI or without a unit (``si_factor``; tested for every exercise).
SI_FACTORS = {
    "µs": 1e-6, "ms": 1e-3,
    "µm": 1e-6, "mm": 1e-3, "cm²": 1e-4,
    "mA": 1e-3, "mV": 1e-3,
    "%": 1e-2,
    "A/mm": 1e3, "A/(mm·s)": 1e3, "A·s/mm": 1e3,
    "N/µm": 1e6,
    "N·mm²/A²": 1e-6, "mm⁴/A⁴": 1e-12,
    "rpm": math.pi / 30, "rpm/s": math.pi / 30,      # to rad/s and rad/s²
}
#: A unit made of these symbols (joined by / · ( ) ² ³ ⁴ 1) is SI: unprefixed only, ``mm`` is not ``m``.
SI_SYMBOLS = frozenset(("m", "kg", "s", "A", "K", "mol", "cd", "rad", "sr", "Hz", "N", "Pa", "J", "W", "C",
                        "V", "F", "Ω", "S", "Wb", "T", "H"))
_SI_OPERATORS = re.compile(r"[/·()²³⁴1]+")
#: Shown as they are used: a pure number, a factor, a count of samples, a matrix whose entries are SI.
UNSCALED = frozenset(("", "×", "samples", "SI"))


@cache
def si_factor(unit: str) -> float:
    """The factor that takes a value shown in ``unit`` to SI; ``ParameterError`` for a unit that is
    neither in ``SI_FACTORS`` nor made of SI symbols (a prefixed unit nobody listed)."""
    if unit in SI_FACTORS:
        return SI_FACTORS[unit]
    symbols = [s for s in _SI_OPERATORS.split(unit) if s]
    if unit in UNSCALED or (symbols and all(s in SI_SYMBOLS for s in symbols)):
        return 1.0
    raise ParameterError(f"unit {unit!r} has no known SI factor: add it to parameters.SI_FACTORS")


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


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

    @cached_property
    def numeric(self) -> bool:
        """A number, or a choice among numbers (their texts, e.g. "-0.5" mm); kept, as ``in_si``
        asks it of every control each time an exercise builds its set-up."""
        return all(_is_number(choice) for choice in self.choices)

    def si(self, values: dict) -> float:
        """This control's value in ``values`` in SI units: value × ``si_factor(unit)`` (the same
        multiplication as by hand, so ``x * 1e-6`` keeps its last bit); a choice read as a number."""
        value = values[self.name]
        return (float(value) if self.choices else value) * si_factor(self.unit)

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


class SiValues(Mapping):
    """The numeric controls of ``values`` in SI units, by name (``Parameter.si``), each converted
    when it is read: a computation that reads ``sensor_lag_us`` through it reads only that control
    of ``values`` (``lab_modules.memo.ReadValues`` then finds what it depends on)."""

    def __init__(self, parameters: Iterable[Parameter], values: dict):
        self.numeric = {p.name: p for p in parameters if p.numeric}
        self.values = values

    def __getitem__(self, name: str) -> float:
        if name not in self.numeric or name not in self.values:
            raise KeyError(name)
        return self.numeric[name].si(self.values)

    def __iter__(self) -> Iterator[str]:
        return (name for name in self.numeric if name in self.values)

    def __len__(self) -> int:
        return sum(1 for _ in self)


def in_si(parameters: Iterable[Parameter], values: dict) -> SiValues:
    """The numeric controls of ``values`` in SI units, by name (``Parameter.si``): read once where
    the physics starts, ``si["sensor_lag_us"]`` is T_mx in s.  Controls absent from ``values`` and
    choices among words are left out; each is read from ``values`` only when asked for."""
    return SiValues(parameters, values)
