"""Pole sets, their categories and their modes, evaluated headless: ``view`` gives the data
object (``PoleView``) that ``app.panels.pole_map`` draws.

Every exercise reports its poles as named sets (``Analysis.poles``) and declares the
category of each (``Exercise.pole_categories``): the open-loop plant, the closed loop, a
filter's error dynamics or a state-feedback regulator.  Each category keeps one colour in
every exercise (issue 11, defect 15); a test fails for a reported set whose category is
not declared, and for a set name two exercises declare differently.

Each mode (a real pole or a complex pair) gets a number, by category, then set, then from
the most unstable down, with its kind, natural frequency f_n = |s|/2π and damping
ζ = −Re s/|s|.  Where an exercise gives the state matrix whose eigenvalues are a set
(``Exercise.mode_matrices``), each pole takes the name of the physics whose states take
the largest part in it (participation factors, ``analysis.name_modes``), so a name follows
the physics when a slider moves the pole; a name the exercise gives (``Exercise.mode_names``)
wins.
"""

from __future__ import annotations

import functools
import threading
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np

from lab_modules import analysis
from lab_modules.evaluation.root_locus import LOCUS_CACHE, NOT_IN_LOCUS, Locus, locus
from lab_modules.exercises import Exercise, PoleCategory, registry
from lab_modules.formatting import number


@dataclass(frozen=True)
class Category:
    name: str
    color: str
    meaning: str


#: The lab's pole categories (``PoleCategory``), in the order of the legend and the table.
CATEGORIES = (
    Category(PoleCategory.PLANT.value, "#7f7f7f", "plant / open loop (no feedback)"),
    Category(PoleCategory.CLOSED_LOOP.value, "#1f77b4", "closed loop (plant, filter and controller together)"),
    Category(PoleCategory.FILTER_ERROR.value, "#d62728",
             "filter error (A − A K C): how fast an estimate forgets its error"),
    Category(PoleCategory.REGULATOR.value, "#2ca02c", "state-feedback regulator (A − B K)"),
)
BY_NAME = {c.name: c for c in CATEGORIES}


def declared_categories(exercise: Exercise, values: dict, poles: dict) -> dict[str, Category]:
    """The category of each set of ``poles`` as the exercise declares it at these values
    (``Exercise.pole_categories``); a set it does not declare counts as ``category`` says."""
    declared = exercise.pole_categories(values)
    return {name: BY_NAME[declared[name].value] if name in declared else category(name) for name in poles}


@functools.cache
def lab_categories() -> dict[str, Category]:
    """The categories every registered exercise declares at its default values, by set name."""
    return {name: BY_NAME[kind.value] for exercise in registry().values()
            for name, kind in exercise.pole_categories(exercise.resolve()).items()}


def category(set_name: str) -> Category:
    """The category the lab's exercises declare for a pole set of this name (one name, one
    category in every exercise: tested); a name no exercise declares counts as plant."""
    return lab_categories().get(set_name, BY_NAME[PoleCategory.PLANT.value])


# -- modes --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Mode:
    """One real pole or complex pair (the upper one) of a set."""

    number: int
    set_name: str
    pole: complex
    category: Category            # the set's
    name: str | None = None       # the exercise's physical name (``Exercise.mode_names``), if any
    shares: tuple = ()            # ((state label, participation share), ...), largest first (``analysis.name_modes``)

    @property
    def is_real(self) -> bool:
        return abs(self.pole.imag) <= 1e-9 * max(abs(self.pole), 1.0)

    @property
    def natural_rad_s(self) -> float:
        return float(abs(self.pole))

    @property
    def natural_hz(self) -> float:
        return self.natural_rad_s / (2 * np.pi)

    @property
    def damping(self) -> float:
        return float(-self.pole.real / abs(self.pole)) if abs(self.pole) > 0 else 1.0

    @property
    def kind(self) -> str:
        if self.is_real:
            if self.pole.real > 0:
                return "unstable real pole (diverges)"
            if self.pole.real == 0:
                return "integrator (s = 0)"
            return f"real, τ = {duration_text(-1.0 / self.pole.real)}"
        if self.pole.real > 0:
            return "unstable oscillation"
        return "lightly damped oscillation" if self.damping < 0.1 else "oscillation"

    @property
    def label(self) -> str:
        """The mode's physical name where the exercise gives one (marked if unstable), else its kind."""
        if not self.name:
            return self.kind
        return f"{self.name} (unstable)" if self.pole.real > 0 and "unstable" not in self.name else self.name


def duration_text(seconds: float) -> str:
    """A time constant in ms below 1 s, else in s (3 significant digits)."""
    return f"{number(seconds * 1e3)} ms" if seconds < 1 else f"{number(seconds)} s"


def modes(poles: dict[str, np.ndarray], names: dict[str, list] | None = None,
          shares: dict[str, list] | None = None, categories: dict[str, Category] | None = None) -> list[Mode]:
    """The modes of all sets, numbered by category (``CATEGORIES`` order), then set, then
    from the most unstable (largest Re s) down; ``names`` (``Exercise.mode_names``: per set,
    one name or None per pole in the set's order) names them; ``categories`` (by set name,
    ``declared_categories``) sorts them, ``category`` for a set it leaves out."""
    names, shares, categories = names or {}, shares or {}, categories or {}
    kinds = {set_name: categories.get(set_name) or category(set_name) for set_name in poles}
    sets = sorted(poles, key=lambda set_name: CATEGORIES.index(kinds[set_name]))
    found = []
    for set_name in sets:
        ps = np.asarray(poles[set_name], dtype=complex)
        given = list(names.get(set_name) or [])
        given += [None] * (ps.size - len(given))
        parts = list(shares.get(set_name) or [])
        parts += [()] * (ps.size - len(parts))
        upper = [(p, given[k], parts[k] or ()) for k, p in enumerate(ps) if p.imag >= -1e-9 * max(abs(p), 1.0)]
        found += [(set_name, complex(p.real, abs(p.imag) if abs(p.imag) > 1e-9 * max(abs(p), 1.0) else 0.0),
                   name, part) for p, name, part in sorted(upper, key=lambda item: -item[0].real)]
    return [Mode(k + 1, set_name, p, kinds[set_name], name, part)
            for k, (set_name, p, name, part) in enumerate(found)]


# -- what the Pole map tab shows ----------------------------------------------------------------
@dataclass(frozen=True)
class PoleView:
    """The pole sets of an analysis with their categories, mode names and root locus."""

    poles: dict
    locus: Locus | None = None
    names: dict = field(default_factory=dict)     # ``Exercise.mode_names`` of these poles
    shares: dict = field(default_factory=dict)    # per set, per pole: its states' participation shares
    categories: dict = field(default_factory=dict)   # set name -> Category (``declared_categories``)

    def category(self, set_name: str) -> Category:
        """The set's category as its exercise declares it (else ``category``)."""
        return self.categories.get(set_name) or category(set_name)

    def modes(self) -> list[Mode]:
        return modes(self.poles, self.names, self.shares, self.categories)

    def same_as(self, other: PoleView | None) -> bool:
        return (other is not None and self.poles.keys() == other.poles.keys() and self.names == other.names
                and self.categories == other.categories
                and all(np.array_equal(self.poles[k], other.poles[k]) for k in self.poles)
                and (self.locus is other.locus or (
                    self.locus is not None and other.locus is not None and self.locus.label == other.locus.label
                    and np.array_equal(self.locus.poles, other.locus.poles))))


def view(exercise: Exercise, values: dict, poles: dict[str, np.ndarray]) -> PoleView:
    """The pole view of an analysis with the exercise's categories and mode names; the root
    locus (or the names) are left out if they cannot be computed here."""
    categories = declared_categories(exercise, values, poles)
    try:
        names, shares = _cached_physical_names(exercise, values, poles)
    except (ValueError, ArithmeticError, KeyError, IndexError):             # incl. LinAlgError
        names, shares = {}, {}
    try:
        for set_name, given in exercise.mode_names(values, poles).items():   # a given name wins
            derived = names.get(set_name) or [None] * len(given)
            names[set_name] = [g if g is not None else d for g, d in zip(given, derived)]
    except (ValueError, ArithmeticError, KeyError, IndexError):
        pass
    try:
        return PoleView(poles, locus(exercise, values), names, shares, categories)
    except (ValueError, ArithmeticError, KeyError, NotImplementedError):
        return PoleView(poles, names=names, shares=shares, categories=categories)


_names_cache: OrderedDict = OrderedDict()
_names_lock = threading.Lock()


def _cached_physical_names(exercise: Exercise, values: dict, poles: dict) -> tuple[dict, dict]:
    """``physical_names`` of the exercise's ``mode_matrices``, kept per setting (the analysis
    thread redraws the same setting several times; an uploaded recording is never cached)."""
    key = None
    if values.get("data") is None:
        key = (exercise.name, tuple(sorted((k, v) for k, v in values.items() if k not in NOT_IN_LOCUS)),
               tuple((name, np.asarray(p, dtype=complex).tobytes()) for name, p in poles.items()))
        with _names_lock:
            if key in _names_cache:
                names, shares = _names_cache[key]
                return {k: list(v) for k, v in names.items()}, dict(shares)
    names, shares = physical_names(exercise.mode_matrices(values), poles)
    if key is not None:
        with _names_lock:                             # the analysis threads of all tabs share it
            _names_cache[key] = ({k: list(v) for k, v in names.items()}, dict(shares))
            while len(_names_cache) > LOCUS_CACHE:
                _names_cache.popitem(last=False)
    return names, shares


def physical_names(matrices: dict, poles: dict[str, np.ndarray], tolerance: float = 1e-5) -> tuple[dict, dict]:
    """(names, shares) of the pole sets that ``Exercise.mode_matrices`` gives a state matrix for:
    each pole takes the name and participation shares of the eigenvalue of that matrix it is
    (``analysis.name_modes``; matched within ``tolerance`` × |s|, None where none matches)."""
    names, shares = {}, {}
    for set_name, (A, states, T) in matrices.items():
        if set_name not in poles:
            continue
        named = analysis.name_modes(A, states, T)
        names[set_name], shares[set_name] = [], []
        for p in np.asarray(poles[set_name], dtype=complex):
            distance = [abs(p - m.pole_s) for m in named]
            k = int(np.argmin(distance)) if distance else -1
            close = k >= 0 and distance[k] <= tolerance * max(abs(p), 1.0)
            names[set_name].append(named[k].name if close else None)
            shares[set_name].append(named[k].shares if close else ())
    return names, shares


def dominant_decay_rad_s(poles: dict[str, np.ndarray]) -> float:
    """Decay rate |Re s| up to which a pole counts as dominant: twice the median
    decay rate, which leaves out the sensor-lag and amplifier poles (thousands
    of rad/s) that squash the real axis, but keeps the rotor, controller and
    filter poles around them."""
    decay = np.abs(np.concatenate([np.asarray(p, dtype=complex) for p in poles.values()] or [np.zeros(0)]).real)
    return 2.0 * float(np.median(decay)) if decay.size else np.inf
