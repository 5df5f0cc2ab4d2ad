"""The lab's exercises.  Each module defines one ``EXERCISE``; the app renders
any of them generically (parameters, scope charts, pole map, readouts)."""

from __future__ import annotations

import enum
import importlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from lab_modules.claims import Claim
from lab_modules.parameters import Parameter, ParameterError, resolve


@dataclass(frozen=True)
class Series:
    """One line of a scope chart: a trace column scaled into display units."""

    label: str
    column: str
    scale: float
    color: str


@dataclass(frozen=True)
class Chart:
    """A rolling oscilloscope chart; ``band`` = (centre column, sigma column) draws ±3σ.
    ``band_in_range`` False: the y range follows the series alone and the band is cut at its
    edges (a filter's wide starting band would squash the estimate's detail)."""

    title: str
    unit: str
    series: tuple[Series, ...]
    band: tuple[str, str] | None = None
    band_in_range: bool = True


@dataclass(frozen=True)
class Plot:
    """A static x-y chart of the analysis (step response, pole paths, k_x over x ...).

    ``series`` holds (label, y values, CSS colour); NaN in y is a gap.  Labels
    carry units, e.g. ``"displacement x [µm]"``."""

    title: str
    x_label: str
    y_label: str
    x: np.ndarray
    series: tuple[tuple[str, np.ndarray, str], ...]
    points: bool = False                              # markers only (scatter)
    log_x: bool = False                               # logarithmic axes (positive values only)
    log_y: bool = False
    shade: tuple[tuple[float, float], ...] = ()       # x intervals shaded in live plots (e.g. fit windows)
    log_decades: int | None = None                    # a log y axis spans at most this many decades below its
                                                      # top (None: the app's default, 4); the data lie above it


@dataclass
class Analysis:
    """What the linear analysis says about the current settings."""

    readouts: list[tuple[str, float, str]]           # (label, value, unit)
    poles: dict[str, np.ndarray]                      # name -> continuous-equivalent poles [rad/s]
    notes: list[str] = field(default_factory=list)
    plots: list[Plot] = field(default_factory=list)


#: The panels of a tab that show an exercise's analysis (``Exercise.analyse_panel``): the readouts
#: under the scope, the pole maps, and the Analysis tab's readouts and plots.
SCOPE, POLE_MAP, ANALYSIS = "Scope", "Pole map", "Analysis"
PANELS = (SCOPE, POLE_MAP, ANALYSIS)


def results(result: Analysis | Iterator[Analysis]) -> Iterator[Analysis]:
    """The results of an ``analyse`` or ``analyse_panel`` call one by one: it returns one ``Analysis``
    or yields a quick one, then fuller ones (computed as they are asked for)."""
    if isinstance(result, Analysis):
        yield result
    else:
        yield from result


def panels_together(exercise: Exercise, values: dict) -> Iterator[Analysis]:
    """The parts of ``exercise.analyse_panel`` as one analysis: each panel's first result together,
    then each panel's last (readouts and notes: the Scope's, then the Analysis tab's; poles: the
    Pole map's; a panel without a part of its own takes it from the Scope's result)."""
    if type(exercise).analyse_panel is Exercise.analyse_panel:
        raise NotImplementedError(f"exercise {exercise.name!r} implements neither analyse nor analyse_panel")
    parts = {panel: exercise.analyse_panel(values, panel) for panel in PANELS}
    found = {panel: results(part) for panel, part in parts.items() if part is not None}
    first = {panel: next(found[panel]) for panel in found}
    yield _together(first)
    yield _together({panel: _last(found[panel], first[panel]) for panel in found})


def _together(parts: dict[str, Analysis]) -> Analysis:
    """One ``Analysis`` of the panels' ``parts`` (a panel missing from them shows the Scope's part)."""
    scope = parts[SCOPE]
    tab = parts.get(ANALYSIS)
    return Analysis(scope.readouts + (tab.readouts if tab else []), parts.get(POLE_MAP, scope).poles,
                    scope.notes + (tab.notes if tab else []), scope.plots + (tab.plots if tab else []))


def _last(found: Iterator[Analysis], first: Analysis | None = None) -> Analysis:
    """The last of ``found`` (``first`` if it holds none)."""
    last = first
    for last in found:
        pass
    return last


class PoleCategory(enum.Enum):
    """What a pole set of ``Analysis.poles`` is (``Exercise.pole_categories``): the pole map draws
    each category in one colour in every exercise and lists the categories in this order."""

    PLANT = "plant"                    # the plant, open loop (no feedback)
    CLOSED_LOOP = "closed loop"        # plant, filter and controller together
    FILTER_ERROR = "filter error"      # a filter's error dynamics (A − A K C), an adaptive weight's error
    REGULATOR = "regulator"            # a state-feedback regulator (A − B K)


@dataclass(frozen=True)
class Action:
    """A button of an exercise that runs a longer computation on demand (a Monte-Carlo run ...).

    ``method`` names an exercise method taking the parameter ``values``: it returns an
    ``Analysis`` or yields several (progress first, the result last; ``poles`` are not
    shown).  The app runs it in the background: the tab stays live, a second press
    starts it afresh, an exercise switch stops it at its next yield."""

    label: str                                        # the button's text
    method: str
    hint: str = ""


class Simulation(Protocol):
    """What the app needs of an exercise's time simulation."""

    sample_time_s: float
    columns: tuple[str, ...]                          # trace columns after the time column

    def advance(self, n_steps: int) -> np.ndarray:
        """Up to ``n_steps`` samples as rows (time [s], *columns); fewer once stopped."""

    def status_message(self) -> str:
        """'' while running; a sentence saying why it stopped (touchdown, divergence ...)."""

    # Optional, for simulations with a Kalman filter (the app's filter inspector):
    # ``filter_state() -> dict | None``: the filter at the sample of the last ``advance(1)``
    # (None if the last advance ran more samples: the loops then keep nothing extra), after its
    # correction with that sample's measurement: ``title``, ``time_s``, ``states``
    # ((label, SI unit), ...), ``x`` (n,), ``P`` (n, n), ``measurements`` ((label, unit), ...),
    # ``K`` (n, m), ``innovation`` (m,) and ``innovation_sigma`` (m,) = √diag(S) against the
    # prior (K and the innovation None for a filter that corrects continuously).
    # ``filter_tape() -> estimators.filter_history.FilterTape``: for a linear filter, the bounded
    # record of what it read (its matrices, the prior at the start, per sample u, y and the true
    # state): the app's filter debugger replays its history from it (step back, branch with another
    # Q or R, covariance ellipses, NEES/NIS), and ``python -m app run --filter-history`` prints it.


class SceneView(Protocol):
    """An optional 3D view of an exercise in the tab's viser scene; after ``attach``, ``root`` is
    the frame every one of its nodes hangs from (the filter debugger hides it to show its own)."""

    root: object

    def attach(self, scene) -> None:
        """Add the scene nodes once (``scene`` is the tab's ``viser.SceneApi``)."""

    def update(self, values: dict) -> None:
        """A parameter changed."""

    def animate(self, wall_time_s: float, latest: dict[str, float]) -> None:
        """Called every display frame; ``latest`` maps each trace column (and
        ``time_s``) to its newest value, empty before the first samples."""


class Exercise:
    """Base class: subclasses set the attributes and implement the methods.

    Every method takes the resolved parameter ``values``; an uploaded data set
    (see ``data_description``) travels in ``values["data"]`` (None: the
    exercise's shipped default)."""

    name: str
    title: str
    worksheet: str                   # file name in static/worksheets (an absolute path is read as is)
    parameters: tuple[Parameter, ...]
    charts: tuple[Chart, ...]
    default_duration_s: float = 1.0
    #: The shortest headless run whose metrics are all defined at the defaults [s] (e.g. one that
    #: reaches the step its metrics measure); ``run --duration`` refuses less.
    min_duration_s: float = 0.01
    data_description: str | None = None   # set: the exercise accepts an uploaded CSV
    download_label: str | None = None     # set: a button offers ``download(values)`` as a file
    claims: tuple[Claim, ...] = ()        # the paper's headline results, measured by ``metrics``
    #: Why the exercise has no feedback loop to grade (then ``open_loops`` stays empty); every
    #: exercise either declares its loops or says here why it has none (tested).
    no_feedback_loop: str = ""
    actions: tuple[Action, ...] = ()      # buttons that run a method in the background (see ``Action``)
    #: (parameter, pole set): a common gain factor and the closed-loop set of ``Analysis.poles`` it
    #: moves; the pole map draws that set's paths as the factor sweeps its range (root locus)
    locus: tuple[str, str] | None = None
    #: Labels of the readouts the worksheet's tasks name (a scope-window readout's without its
    #: " (scope window)"): pinned above the scope, in view without scrolling (tested to exist)
    key_readouts: tuple[str, ...] = ()

    def resolve(self, overrides: dict | None = None) -> dict:
        overrides = dict(overrides or {})
        data = overrides.pop("data", None)
        values = resolve(self.parameters, overrides)
        if self.data_description is not None:
            values["data"] = data
        return values

    def model(self, values: dict) -> dict:
        raise NotImplementedError

    def analyse(self, values: dict) -> Analysis | Iterator[Analysis]:
        """Everything the analysis says at these settings (readouts, poles, notes, static plots); may
        yield a quick result first, then fuller ones.  Headless runs, reports and tests read it whole;
        the app asks each panel for its part (``analyse_panel``).  Default: the parts of
        ``analyse_panel`` together (``panels_together``)."""
        return panels_together(self, values)

    def analyse_panel(self, values: dict, panel: str) -> Analysis | Iterator[Analysis] | None:
        """The part of the analysis one panel shows (``PANELS``), computed only while it is shown:

        * ``SCOPE``: the readouts and notes under the scope, after every slider move: keep it to
          a few milliseconds (the costly figures belong to the Analysis tab);
        * ``POLE_MAP``: ``poles`` (the app adds mode names and the root locus);
        * ``ANALYSIS``: the Analysis tab's readouts, notes and plots (the app adds the margins of
          ``open_loops``).

        Returns an ``Analysis`` or yields a quick one first.  The app ignores what a panel does not
        show.  None: the panel shows its part of the Scope's result.  Default (an exercise that does
        not split its analysis): the whole ``analyse`` for the Scope, None for the other panels."""
        return self.analyse(values) if panel == SCOPE else None

    def simulation(self, values: dict) -> Simulation:
        raise NotImplementedError

    def retune(self, simulation: Simulation, values: dict) -> Simulation:
        """The simulation after a parameter change; by default a fresh one."""
        return self.simulation(values)

    @property
    def restarts_on_change(self) -> bool:
        """Whether a parameter change starts a fresh run (the default ``retune``), so the run
        shown so far no longer belongs to the values."""
        return type(self).retune is Exercise.retune

    def metrics(self, values: dict, duration_s: float) -> dict:
        raise NotImplementedError

    def parameter_ranges(self, values: dict) -> dict[str, tuple[float, float]]:
        """Narrower (minimum, maximum) of parameters whose valid range depends on the other values,
        e.g. on the loaded recording's length; the tab's sliders follow them."""
        return {}

    def following_values(self, values: dict) -> dict:
        """Parameters whose value in use follows from the others (e.g. a preset that sets a
        slider's quantity itself), by name; the tab's controls show these values."""
        return {}

    def locus_matrices(self, values: dict, factors: tuple[float, ...]) -> tuple[list[np.ndarray], float | None]:
        """For ``locus``: the state matrices of that closed loop with the parameter at each of
        ``factors`` (the others as in ``values``) and their sample time [s] (None: continuous).
        They must be affine in the factor (it scales the controller's output)."""
        raise NotImplementedError

    def pole_categories(self, values: dict) -> dict[str, PoleCategory]:
        """The category of each pole set ``analyse(values)`` reports in ``Analysis.poles``, by set
        name: the set's colour on the pole map and its place in the table.  Every set an exercise
        reports is declared (tested).  Default: none."""
        return {}

    def mode_names(self, values: dict, poles: dict[str, np.ndarray]) -> dict[str, list[str | None]]:
        """Physical names of the poles of ``Analysis.poles`` (``poles``, as ``analyse`` returned
        them), by set: one name or None per pole in the set's order, a conjugate pair both
        named alike; the pole map's table shows them instead of the generic kind.  Default:
        no names."""
        return {}

    def mode_matrices(self, values: dict) -> dict[str, tuple]:
        """State matrices whose eigenvalues are pole sets of ``Analysis.poles``, by set name:
        (A, states, sample time [s] or None), ``states`` one (label with unit, physics) per state
        of A (``analysis.name_modes``); the pole map names these sets' modes from A's
        eigenvectors, so the names follow the physics when a slider moves a pole.  Default: none."""
        return {}

    def open_loops(self, values: dict) -> dict:
        """Feedback loops broken at the plant input, by name -> open loop L (``control`` LTI
        system, S = 1 / (1 + L)); the app draws their Bode plots, margins and |S|max."""
        return {}

    def live_readouts(self, trace: dict[str, np.ndarray]) -> list[tuple[str, float, str]]:
        """Readouts from the scope's buffer (column name -> samples)."""
        return []

    def live_plots(self, simulation: Simulation) -> list[Plot]:
        """Plots of the running simulation's newest state (e.g. the raw samples of its last
        periods), redrawn by the app a few times a second beside the scope; keep each to a
        few thousand points.  Their number and series must not change during a run."""
        return []

    def scene(self, values: dict) -> SceneView | None:
        return None

    def download(self, values: dict) -> tuple[str, bytes]:
        """A file for the student to keep: (file name, content)."""
        raise ParameterError(f"exercise {self.name!r} offers no download")

    def load_data(self, filename: str, content: bytes):
        """Parse an uploaded file; raise ``ParameterError`` with one line naming the row or column."""
        raise ParameterError(f"exercise {self.name!r} takes no data files")

    def report_figures(self, values: dict) -> list:
        """Figures (``matplotlib.figure.Figure``, no pyplot) that back the claims in
        ``python -m app reproduce --html``; helpers in ``exercises/_figures.py``."""
        return []


def claim_run(exercise: Exercise, claim: Claim, overrides: dict | None = None) -> tuple:
    """The headless run a claim is measured on: (exercise, settings, duration).  Claims
    with the same key share one ``metrics`` call."""
    settings = {**(overrides or {}), **claim.settings}
    duration = claim.duration_s if claim.duration_s is not None else exercise.default_duration_s
    return exercise.name, tuple(sorted(settings.items())), float(duration)


def measure_claims(exercise: Exercise, overrides: dict | None = None,
                   cache: dict | None = None) -> list[float]:
    """Each claim's lab value, in order; each distinct run once (``cache`` keeps the
    metrics across calls, keyed by ``claim_run``).  ``overrides`` (e.g. a seed) apply
    to every run; a claim's own settings win."""
    cache = {} if cache is None else cache
    values = []
    for claim in exercise.claims:
        key = claim_run(exercise, claim, overrides)
        if key not in cache:
            _, settings, duration = key
            cache[key] = exercise.metrics(exercise.resolve(dict(settings)), duration)
        values.append(claim.value_in(cache[key]))
    return values


#: Exercise modules, in the order the lab lists them (each defines ``EXERCISE``).
MODULES = (
    "kalman_noise",
    "ekf_parameters",
    "ekf_disturbance",
    "lqg_vs_pid",
    "sensor_placement",
    "rotor_at_speed",
    "maglev_tracking",
    "maglev_tuning",
    "thrust_liftoff",
    "self_sensing",
    "stiffness_map",
    "adaptive_filter",
)


def registry() -> dict[str, Exercise]:
    """All exercises by name."""
    exercises = (importlib.import_module(f"{__name__}.{module}").EXERCISE for module in MODULES)
    return {e.name: e for e in exercises}


def get(name: str) -> Exercise:
    exercises = registry()
    if name not in exercises:
        raise ParameterError(f"unknown exercise {name!r}: expected one of {', '.join(exercises)}")
    return exercises[name]
