"""The Pole map tab: one colour legend for the whole lab, labelled poles, root loci.

Every exercise reports its poles as named sets (``Analysis.poles``).  Each set
belongs to one of four categories, drawn in the same colour in every exercise
(issue 11, defect 15): the open-loop plant, the closed loop, a filter's error
dynamics and a state-feedback regulator.  ``category`` maps a set's name onto
them; a test checks every exercise's sets are mapped by a rule, not by default.

Each mode (a real pole or a complex pair) gets a number: the table below the
maps lists it with its kind, natural frequency f_n = |s|/2π and damping
ζ = −Re s/|s|, and a top axis on each map puts the number above the mode.

Exercises with a common gain factor (``Exercise.locus``) get the root locus:
the closed-loop poles as the factor sweeps its range, as small dots in the
closed-loop colour, the poles at the current factor drawn large on them.
The closed loop's state matrix is affine in the factor (the factor scales the
controller's output), so two matrices per setting give the whole sweep by
eigenvalues alone (``locus_poles``, cached per setting; tested against the
exercise's own closed-loop poles).
"""

from __future__ import annotations

import re
import threading
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
import viser

from app.panels import scope
from lab_modules import analysis
from lab_modules.exercises import Exercise
from lab_modules.formatting import number

LIGHT_DAMPING = 0.3               # poles below this damping always belong to the dominant view
LOCUS_POINTS = 48                 # factor values per root locus (geometric over the parameter's range)
LOCUS_CACHE = 64                  # settings whose root locus is kept
LABEL_PX, CHAR_PX, LABEL_SPACE_PX = 470, 7, 6   # plot width, label character width, space between labels [px]
MARGIN = 0.08                     # share of the pole span added on each side of a map
#: Parameters that change nothing in the linear analysis (left out of the locus cache key)
NOT_IN_LOCUS = {"seed", "time_scale", "shown_mode", "data"}


@dataclass(frozen=True)
class Category:
    name: str
    color: str
    meaning: str


#: The lab's pole categories, in the order of the legend and the table.
CATEGORIES = (
    Category("plant", "#7f7f7f", "plant / open loop (no feedback)"),
    Category("closed loop", "#1f77b4", "closed loop (plant, filter and controller together)"),
    Category("filter error", "#d62728", "filter error (A − A K C): how fast an estimate forgets its error"),
    Category("regulator", "#2ca02c", "state-feedback regulator (A − B K)"),
)
BY_NAME = {c.name: c for c in CATEGORIES}
LOCUS_COLOR = "#9ecae1"           # the closed-loop colour, light: the root locus
#: (pattern on the set's name, category), first match wins
RULES = (
    (r"error", "filter error"),
    (r"regulator", "regulator"),
    (r"open-loop|open loop|plant|coil", "plant"),
    (r"loop", "closed loop"),
)
MARK_COLOR, MARK_SIZE = "#ff7f0e", 24.0    # the ring around the mode chosen in "Show mode"
#: Marker (size, hollow) of the 1st, 2nd, 3rd ... set of one category in a map
MARKERS = ((9.0, False), (10.0, True), (6.0, False), (13.0, True))


def category(set_name: str) -> Category:
    """The category of a pole set, from its name (``RULES``); unknown names count as plant."""
    return BY_NAME[matched_rule(set_name) or "plant"]


def matched_rule(set_name: str) -> str | None:
    return next((name for pattern, name in RULES if re.search(pattern, set_name, re.IGNORECASE)), None)


def legend_markdown() -> str:
    """The one colour legend of the lab (the same text in every exercise)."""
    dots = " &nbsp; ".join(f'<span style="color:{c.color}">●</span> {c.meaning}' for c in CATEGORIES)
    return (f"**Colours (every exercise):** {dots} &nbsp; <span style=\"color:{LOCUS_COLOR}\">•</span> "
            "root locus: the closed loop's poles as the gain factor sweeps its range. A hollow marker is a "
            "second set of the same kind. The numbers on the top axis are the modes of the table below.")


# -- modes --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Mode:
    """One real pole or complex pair (the upper one) of a set."""

    number: int
    set_name: str
    pole: complex
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
            return f"real, τ = {_duration(-1.0 / self.pole.real)}"
        if self.pole.real > 0:
            return "unstable oscillation"
        return "lightly damped oscillation" if self.damping < 0.1 else "oscillation"

    @property
    def label(self) -> str:
        """The mode's physical name where the exercise gives one (marked if unstable), else its kind."""
        if not self.name:
            return self.kind
        return f"{self.name} (unstable)" if self.pole.real > 0 and "unstable" not in self.name else self.name


def _duration(seconds: float) -> str:
    return f"{number(seconds * 1e3)} ms" if seconds < 1 else f"{number(seconds)} s"


def modes(poles: dict[str, np.ndarray], names: dict[str, list] | None = None,
          shares: dict[str, list] | None = None) -> list[Mode]:
    """The modes of all sets, numbered by category (``CATEGORIES`` order), then set, then
    from the most unstable (largest Re s) down; ``names`` (``Exercise.mode_names``: per set,
    one name or None per pole in the set's order) names them."""
    names, shares = names or {}, shares or {}
    order = {c.name: k for k, c in enumerate(CATEGORIES)}
    sets = sorted(poles, key=lambda name: order[category(name).name])
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
    return [Mode(k + 1, set_name, p, name, part) for k, (set_name, p, name, part) in enumerate(found)]


def _pole(mode: Mode, digits: int = 3) -> str:
    """s of a mode as text: "-12.5" or "-3 ± 4j"."""
    real = number(mode.pole.real, digits)
    return real if mode.is_real else f"{real} ± {number(mode.pole.imag, digits)}j"


def table_markdown(pole_view: PoleView | dict) -> str:
    """The pole table: every mode with its number, set, name (or kind), f_n, ζ and s."""
    if isinstance(pole_view, dict):
        pole_view = PoleView(pole_view)
    rows = ["| # | set | mode | f_n [Hz] | ζ | s [rad/s] |", "|---:|---|---|---:|---:|---|"]
    for m in modes(pole_view.poles, pole_view.names, pole_view.shares):
        dot = f'<span style="color:{category(m.set_name).color}">●</span>'
        rows.append(f"| {m.number} | {dot} {m.set_name} | {m.label} | {number(m.natural_hz)} "
                    f"| {number(m.damping)} | {_pole(m)} |")
    return "\n".join(rows)


# -- root locus -----------------------------------------------------------------------------------
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


# -- the two maps ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class PoleView:
    """What the Pole map tab shows: the pole sets and the root locus."""

    poles: dict
    locus: Locus | None = None
    names: dict = field(default_factory=dict)     # ``Exercise.mode_names`` of these poles
    shares: dict = field(default_factory=dict)    # per set, per pole: its states' participation shares

    def same_as(self, other: PoleView | None) -> bool:
        return (other is not None and self.poles.keys() == other.poles.keys() and self.names == other.names
                and all(np.array_equal(self.poles[k], other.poles[k]) for k in self.poles)
                and (self.locus is other.locus or (
                    self.locus is not None and other.locus is not None and self.locus.label == other.locus.label
                    and np.array_equal(self.locus.poles, other.locus.poles))))


def view(exercise: Exercise, values: dict, poles: dict[str, np.ndarray]) -> PoleView:
    """The pole view of an analysis with the exercise's mode names; the root locus (or the
    names) are left out if they cannot be computed here."""
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
        return PoleView(poles, locus(exercise, values), names, shares)
    except (ValueError, ArithmeticError, KeyError, NotImplementedError):
        return PoleView(poles, names=names, shares=shares)


_names_cache: OrderedDict = OrderedDict()


def _cached_physical_names(exercise: Exercise, values: dict, poles: dict) -> tuple[dict, dict]:
    """``physical_names`` of the exercise's ``mode_matrices``, kept per setting (the analysis
    thread redraws the same setting several times; an uploaded recording is never cached)."""
    key = None
    if values.get("data") is None:
        key = (exercise.name, tuple(sorted((k, v) for k, v in values.items() if k not in NOT_IN_LOCUS)),
               tuple((name, np.asarray(p, dtype=complex).tobytes()) for name, p in poles.items()))
        with _locus_lock:
            if key in _names_cache:
                names, shares = _names_cache[key]
                return {k: list(v) for k, v in names.items()}, dict(shares)
    names, shares = physical_names(exercise.mode_matrices(values), poles)
    if key is not None:
        with _locus_lock:
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


def _dominant(p: np.ndarray, limit: float) -> np.ndarray:
    p = np.asarray(p, dtype=complex)
    damping = -p.real / np.maximum(np.abs(p), 1e-300)
    return p[(np.abs(p.real) <= limit) | (damping < LIGHT_DAMPING)]


def charts(pole_view: PoleView | dict, marked: Mode | None = None) -> tuple[tuple[tuple, dict], tuple[tuple, dict]]:
    """uPlot arguments of the two pole maps: the dominant poles (slow, or lightly
    damped: |Re s| below ``dominant_decay_rad_s`` or damping below
    ``LIGHT_DAMPING``) and all poles; ``marked`` (the "Show mode" choice) ringed on both."""
    if isinstance(pole_view, dict):
        pole_view = PoleView(pole_view)
    poles, path = pole_view.poles, pole_view.locus
    limit = dominant_decay_rad_s(poles)
    numbered = modes(poles, pole_view.names, pole_view.shares)
    chosen = {name: _dominant(p, limit) for name, p in poles.items()}
    path_points = np.zeros(0, dtype=complex) if path is None else path.poles.ravel()
    path_points = path_points[np.isfinite(path_points)]
    title = f"Dominant poles (Re s > −{limit:.0f} rad/s or damping ζ < {LIGHT_DAMPING})"
    shown_modes = [m for m in numbered if _dominant(np.array([m.pole]), limit).size]
    in_dominant = marked if marked is not None and _dominant(np.array([marked.pole]), limit).size else None
    return (pole_map(chosen, title, shown_modes, _dominant(path_points, limit), path, in_dominant),
            pole_map(poles, "All poles", numbered, path_points, path, marked))


def span(points: np.ndarray) -> tuple[tuple[float, float], tuple[float, float]]:
    """(x range, y range) [rad/s] of a map: every point and the imaginary axis inside, with
    ``MARGIN`` of the span on each side; the y range symmetric (conjugate pairs)."""
    points = np.asarray(points, dtype=complex)
    real = np.append(points.real, 0.0)
    low, high = float(real.min()), float(real.max())
    width = high - low or max(abs(low), 1.0)
    reach = float(np.abs(points.imag).max()) if points.size else 0.0
    if reach == 0.0:                                  # all poles real: a square-ish view of the real axis
        reach = 0.5 * width
    return (low - MARGIN * width, high + MARGIN * width), (-(1 + MARGIN) * reach, (1 + MARGIN) * reach)


def _label_text(group: list[Mode]) -> str:
    numbers = sorted(m.number for m in group)
    return ",".join(map(str, numbers)) if len(numbers) <= 2 else f"{numbers[0]},{numbers[1]},+{len(numbers) - 2}"


def _labels(shown: list[Mode], x_range: tuple[float, float]) -> tuple[tuple[float, ...], tuple[str, ...]]:
    """Top-axis positions and texts of the mode numbers; labels that would overlap (at
    ``LABEL_PX`` of plot width) merge into one ("3,7" or "3,7,+2": two more)."""
    px_per_unit = LABEL_PX / (x_range[1] - x_range[0])

    def centre(group: list[Mode]) -> float:
        return float(np.mean([m.pole.real for m in group]))

    def overlap(a: list[Mode], b: list[Mode]) -> bool:
        room = (len(_label_text(a)) + len(_label_text(b))) * CHAR_PX / 2 + LABEL_SPACE_PX
        return (centre(b) - centre(a)) * px_per_unit < room

    groups = [[m] for m in sorted(shown, key=lambda m: m.pole.real)]
    merged = True
    while merged:
        merged = False
        for k in range(len(groups) - 1):
            if overlap(groups[k], groups[k + 1]):
                groups[k:k + 2] = [groups[k] + groups[k + 1]]
                merged = True
                break
    return tuple(centre(g) for g in groups), tuple(_label_text(g) for g in groups)


def pole_map(poles: dict[str, np.ndarray], title: str, shown: list[Mode] | None = None,
             path_points: np.ndarray | None = None, path: Locus | None = None,
             marked: Mode | None = None) -> tuple[tuple, dict]:
    """A pole map as a scatter plot over one shared, sorted real axis (each pole
    set a series with gaps where the others have their poles), with the
    imaginary axis drawn as a dashed line between two extra rows at Re s = 0,
    the root locus (if any) as small dots under the poles, and explicit ranges
    that hold every point (issue 11, defect 3)."""
    path_points = np.zeros(0, dtype=complex) if path_points is None else np.asarray(path_points, dtype=complex)
    x_range, y_range = span(np.concatenate([np.asarray(p, dtype=complex) for p in poles.values()] + [path_points]))
    layers = []                                       # (series options, points), drawn in this order
    if path is not None:
        layers.append((viser.uplot.Series(
            label=path.label, stroke=LOCUS_COLOR, width=0,
            points=viser.uplot.Series_Points(show=True, size=4.0, width=0, fill=LOCUS_COLOR, stroke=LOCUS_COLOR)),
            path_points))
    counts: dict[str, int] = {}
    for name, points in poles.items():
        color = category(name).color
        size, hollow = MARKERS[min(counts.get(color, 0), len(MARKERS) - 1)]
        counts[color] = counts.get(color, 0) + 1
        layers.append((viser.uplot.Series(
            label=name, stroke=color, width=0,
            points=viser.uplot.Series_Points(show=True, size=size, width=2.0,
                                             fill="#ffffff" if hollow else color, stroke=color)),
            np.asarray(points, dtype=complex)))
    if marked is not None:                            # a ring around the chosen mode (and its mirror)
        ring = np.array([marked.pole] if marked.is_real else [marked.pole, np.conj(marked.pole)])
        layers.append((viser.uplot.Series(
            label=f"mode #{marked.number}: {marked.label}", stroke=MARK_COLOR, width=0,
            points=viser.uplot.Series_Points(show=True, size=MARK_SIZE, width=3.0, fill="rgba(0,0,0,0)",
                                             stroke=MARK_COLOR)), ring))
    axis_ends = np.array([y_range[0], y_range[1]]) / (1 + MARGIN) * 1j
    layers.append((viser.uplot.Series(label="Re s = 0", stroke="#000000", width=1, dash=(6.0, 4.0),
                                      points=viser.uplot.Series_Points(show=False)), axis_ends))
    rows = sorted((p.real, p.imag, k) for k, (_, points) in enumerate(layers) for p in points)
    x = np.array([r[0] for r in rows])
    columns = [np.full(len(x), np.nan) for _ in layers]
    for row, (_, value, k) in enumerate(rows):
        columns[k][row] = value
    splits, texts = _labels(shown if shown is not None else modes(poles), x_range)
    axes = (viser.uplot.Axis(label="Re s [rad/s]"), viser.uplot.Axis(label="Im s [rad/s]", size=scope.Y_AXIS_SIZE),
            viser.uplot.Axis(side=0, scale="x", label="mode # (table below)", labelSize=16, size=20,
                             splits=splits, values=texts, grid={"show": False}, ticks={"show": True, "size": 4}))
    return (x, *columns), {
        "series": (viser.uplot.Series(label="Re s [rad/s]"), *(options for options, _ in layers)),
        "title": title, "legend": viser.uplot.Legend(live=False), "padding": scope.PADDING, "axes": axes,
        "scales": {"x": viser.uplot.Scale(time=False, range=x_range),
                   "y": viser.uplot.Scale(auto=False, min=y_range[0], max=y_range[1])}}


# -- "Show mode": one mode ringed on the maps, with its name and state participation ------------
NO_MODE = "(none)"
DETAIL_DIGITS = 4                 # s and f_n of the chosen mode: one digit more than the table


def mode_choice(mode: Mode) -> str:
    """The "Show mode" dropdown's text of a mode."""
    return f"#{mode.number} {mode.label} ({number(mode.natural_hz)} Hz)"


def mode_choices(pole_view: PoleView) -> tuple[str, ...]:
    return (NO_MODE, *(mode_choice(m) for m in modes(pole_view.poles, pole_view.names, pole_view.shares)))


def follow(pole_view: PoleView, previous: Mode | None) -> Mode | None:
    """The mode of ``pole_view`` that is ``previous`` after a slider moved: the same set and
    name (the nearest pole if several share it), else the same number; None if none is left."""
    if previous is None:
        return None
    found = modes(pole_view.poles, pole_view.names, pole_view.shares)
    alike = [m for m in found if m.set_name == previous.set_name and m.label == previous.label]
    if alike:
        return min(alike, key=lambda m: abs(m.pole - previous.pole))
    return next((m for m in found if m.number == previous.number and m.set_name == previous.set_name), None)


def chosen(pole_view: PoleView, choice: str) -> Mode | None:
    return next((m for m in modes(pole_view.poles, pole_view.names, pole_view.shares) if mode_choice(m) == choice),
                None)


def detail_markdown(mode: Mode | None) -> str:
    """What the student reads about the chosen mode: name, set, s, f_n, ζ, time constant and the
    states that take part in it (participation factors, ``analysis.participation``)."""
    if mode is None:
        return ("*Pick a mode in “Show mode” to ring it on both maps (orange) and read its name, "
                "frequency, damping and which states take part in it.*")
    decay = _duration(-1.0 / mode.pole.real) if mode.pole.real < 0 else "— (not decaying)"
    lines = [(f"**Mode #{mode.number}: {mode.label}** "
             f'(<span style="color:{category(mode.set_name).color}">●</span> {mode.set_name})'), "",
             "| s [rad/s] | f_n [Hz] | ζ | time constant τ = −1/Re s |", "|---|---:|---:|---:|",
             (f"| {_pole(mode, DETAIL_DIGITS)} | {number(mode.natural_hz, DETAIL_DIGITS)} "
              f"| {number(mode.damping)} | {decay} |")]
    shown = [(label, share) for label, share in mode.shares if share >= 0.01]
    if shown:
        lines += ["", "State participation (share of the mode; the name is the physics with the largest share):", "",
                  "| state [unit] | share |", "|---|---:|"]
        lines += [f"| {label} | {100 * share:.0f} % |" for label, share in shown]
    else:
        lines += ["", "*(named from the plant model's structure; no participation factors for this set)*"
                  if mode.name else "*(no state matrix for this set: generic kind only)*"]
    return "\n".join(lines)
