"""Every claim of an exercise measured headless: each distinct run (exercise, settings,
run length, seed) once, each claim's value per seed and its verdict against the range the
lab holds itself to (``lab_modules.claims.Claim``).  Read by ``python -m app reproduce``,
the worksheets' claims tables and the tests."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from lab_modules.claims import Claim, format_value, settings_text, status
from lab_modules.exercises import Exercise, claim_run
from lab_modules.parameters import ParameterError

#: What a broken metric or figure raises: reported in the table, not a crash of the whole run.
MEASUREMENT_ERRORS = (ArithmeticError, AttributeError, IndexError, KeyError, LookupError, RuntimeError,
                      TypeError, ValueError, ParameterError, np.linalg.LinAlgError)
FULL_SEEDS = (0, 1, 2, 3, 4)
QUICK_SEEDS = (0,)
PASS, DEVIATION, FAIL = "pass", "deviation (holds)", "FAIL"


@dataclass
class Row:
    """One claim, measured."""

    exercise: str
    claim: Claim
    values: list[float] = field(default_factory=list)     # per seed (seed 0 first)
    error: str = ""                                        # the metric could not be measured

    @property
    def value(self) -> float | None:
        return self.values[0] if self.values else None

    @property
    def status(self) -> str:
        if self.error or not self.values or not all(self.claim.holds(v) for v in self.values):
            return FAIL
        return status(self.claim, self.value)

    @property
    def reason(self) -> str:
        """Why a row is a deviation or a failure (empty for a plain pass)."""
        if self.error:
            return f"not measured: {self.error}"
        if self.status == FAIL:
            bad = [v for v in self.values if not self.claim.holds(v)]
            seeds = "" if len(self.values) == 1 else f" on {len(bad)} of {len(self.values)} seeds"
            return f"{format_value(bad[0], self.claim.accept)} outside {self.claim.accept_text()}{seeds}" + (
                f"; {self.claim.note}" if self.claim.deviation else "")
        return self.claim.note if self.claim.deviation else ""

    def quantity_text(self) -> str:
        settings = settings_text(self.claim.settings)
        return self.claim.quantity + (f" [{settings}]" if settings else "")

    def as_dict(self) -> dict:
        claim = self.claim
        return {"exercise": self.exercise, "source": claim.source, "quantity": claim.quantity,
                "paper": claim.paper, "metric": claim.metric, "value": self.value, "values_by_seed": self.values,
                "unit": claim.unit, "accept": list(claim.accept), "accept_text": claim.accept_text(),
                "settings": claim.settings, "duration_s": claim.duration_s, "deviation": claim.deviation,
                "note": claim.note, "status": self.status, "reason": self.reason}


def seeds_for(exercise: Exercise, quick: bool) -> tuple[int, ...]:
    has_seed = any(p.name == "seed" for p in exercise.parameters)
    return QUICK_SEEDS if quick or not has_seed else FULL_SEEDS


def measure(exercises: list[Exercise], quick: bool, log=None) -> list[Row]:
    """Every claim of ``exercises``, each distinct run (exercise, settings, duration, seed) once."""
    rows = []
    for exercise in exercises:
        started = time.perf_counter()
        seeds = seeds_for(exercise, quick)
        cache: dict = {}
        ex_rows = [Row(exercise.name, claim) for claim in exercise.claims]
        for seed in seeds:
            overrides = {"seed": seed} if seed != 0 or len(seeds) > 1 else {}
            for row in ex_rows:
                if row.error:
                    continue
                key = claim_run(exercise, row.claim, overrides)
                try:
                    if key not in cache:
                        cache[key] = exercise.metrics(exercise.resolve(dict(key[1])), key[2])
                    row.values.append(row.claim.value_in(cache[key]))
                except MEASUREMENT_ERRORS as error:  # a broken metric is a failed claim
                    row.error = f"{type(error).__name__}: {error}"
        if log:
            log(f"{exercise.name}: {len(ex_rows)} claims, {len(cache)} runs, "
                f"{time.perf_counter() - started:.1f} s")
        rows.extend(ex_rows)
    return rows
