"""The lab's exercises.  Each module defines one ``EXERCISE``; the app renders
any of them generically (parameters, scope charts, pole map, readouts)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..parameters import Parameter, ParameterError, resolve


@dataclass(frozen=True)
class Series:
    """One line of a scope chart: a trace column scaled into display units."""

    label: str
    column: str
    scale: float
    color: str


@dataclass(frozen=True)
class Chart:
    """A rolling oscilloscope chart; ``band`` = (centre column, sigma column) draws ±3σ."""

    title: str
    unit: str
    series: tuple[Series, ...]
    band: tuple[str, str] | None = None


@dataclass
class Analysis:
    """What the linear analysis says about the current settings."""

    readouts: list[tuple[str, float, str]]           # (label, value, unit)
    poles: dict[str, np.ndarray]                      # name -> continuous-equivalent poles [rad/s]
    notes: list[str] = field(default_factory=list)


class Exercise:
    """Base class: subclasses set the attributes and implement the methods."""

    name: str
    title: str
    worksheet: str                   # file name in static/worksheets
    parameters: tuple[Parameter, ...]
    charts: tuple[Chart, ...]
    default_duration_s: float = 1.0

    def resolve(self, overrides: dict | None = None) -> dict:
        return resolve(self.parameters, overrides)

    def model(self, values: dict) -> dict:
        raise NotImplementedError

    def analyse(self, values: dict) -> Analysis:
        raise NotImplementedError

    def simulation(self, values: dict):
        raise NotImplementedError

    def metrics(self, values: dict, duration_s: float) -> dict:
        raise NotImplementedError


def registry() -> dict[str, Exercise]:
    """All exercises by name."""
    from . import kalman_noise
    return {e.name: e for e in (kalman_noise.EXERCISE,)}


def get(name: str) -> Exercise:
    exercises = registry()
    if name not in exercises:
        raise ParameterError(f"unknown exercise {name!r}: expected one of {', '.join(exercises)}")
    return exercises[name]
