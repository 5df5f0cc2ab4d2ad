"""The root locus of an exercise with a common gain factor (``Exercise.locus``): the
closed-loop poles as the factor sweeps its range.

The closed loop's state matrix is affine in the factor (the factor scales the
controller's output), so two matrices per setting give the whole sweep by
eigenvalues alone (``locus_poles``, cached per setting; tested against the
exercise's own closed-loop poles).  ``app.panels.pole_map`` draws it.
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from lab_modules import analysis
from lab_modules.exercises import Exercise

LOCUS_POINTS = 48                 # factor values per root locus (geometric over the parameter's range)
LOCUS_CACHE = 64                  # settings whose root locus is kept
#: Parameters that change nothing in the linear analysis (left out of the cache keys)
NOT_IN_LOCUS = {"seed", "time_scale", "shown_mode", "data"}


@dataclass(frozen=True)
class Locus:
    """Closed-loop poles [rad/s] (rows) at each factor value of ``factors``."""

    parameter: str
    label: str
    set_name: str
    factors: np.ndarray
    poles: np.ndarray


_locus_cache: OrderedDict = OrderedDict()
_locus_lock = threading.Lock()


def locus_poles(exercise: Exercise, values: dict, factors: np.ndarray) -> np.ndarray:
    """The locus set's poles [rad/s] at each of ``factors`` (rows), by interpolating the closed
    loop's state matrix between the two ends of ``factors`` (it is affine in the factor)."""
    low, high = float(factors[0]), float(factors[-1])
    (A_low, A_high), T = exercise.locus_matrices(values, (low, high))
    A_low, A_high = np.asarray(A_low, dtype=float), np.asarray(A_high, dtype=float)
    slope = (A_high - A_low) / (high - low)
    rows = [np.linalg.eigvals(A_low + (f - low) * slope) for f in factors]
    poles = np.array(rows)
    return poles if T is None else analysis.z_to_s(poles, T)


def locus(exercise: Exercise, values: dict) -> Locus | None:
    """The exercise's root locus at these settings (None without ``Exercise.locus``); computed
    once per setting of the other parameters (the factor itself only moves the marker)."""
    if exercise.locus is None:
        return None
    parameter_name, set_name = exercise.locus
    key = (exercise.name, tuple(sorted((k, v) for k, v in values.items()
                                       if k not in NOT_IN_LOCUS and k != parameter_name)))
    parameter = next(p for p in exercise.parameters if p.name == parameter_name)
    with _locus_lock:
        cached = _locus_cache.get(key)
        if cached is not None:
            _locus_cache.move_to_end(key)
    if cached is None:
        factors = np.geomspace(parameter.minimum, parameter.maximum, LOCUS_POINTS)
        cached = (factors, locus_poles(exercise, values, factors))
        with _locus_lock:                             # the analysis threads of all tabs share it
            _locus_cache[key] = cached
            while len(_locus_cache) > LOCUS_CACHE:
                _locus_cache.popitem(last=False)
    factors, poles = cached
    unit = f" {parameter.unit}" if parameter.unit else ""
    label = (f"root locus: {set_name}, {parameter.label} {parameter.minimum:g}…{parameter.maximum:g}{unit} "
             f"(now {values[parameter_name]:g})")
    return Locus(parameter_name, label, set_name, factors, poles)
