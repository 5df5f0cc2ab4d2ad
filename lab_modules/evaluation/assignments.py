"""Assignments as data: every student their own plant, a design graded by what it achieves.

An ``Assignment`` names an exercise, the parameters drawn per student (``Variation``: a range),
the parameters the student may not change (``locked``; the drawn ones are locked too), and the
``Spec`` s to meet: a metric that ``Exercise.metrics`` computes, a bound and points.

* A student's variant (``variant``) is drawn reproducibly from the assignment's code and the
  student's id: the same pair always gives the same plant, and no student can compute another's
  without that student's id.
* A submission (``grade_submission``) is the student's settings only: the metrics are computed
  here, headless, on the student's variant; a number measured elsewhere is never read.
* ``counted_score``: the best or the last submission counts, as the assignment says.

Pure data and evaluation: the store keeps ``Assignment.as_json()``; the app draws the results.
"""

from __future__ import annotations

import hashlib
import math
import re
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime

import numpy as np

from lab_modules.exercises import Exercise, get
from lab_modules.parameters import Parameter, ParameterError

RELATIONS = ("<=", ">=")
COUNTS = ("best", "last")
STUDENT_ID_CHARACTERS = 64
SIGNIFICANT_DIGITS = 4            # a drawn value as a student reads it on the slider
VARY_FORM = "NAME=LOW..HIGH, e.g. sensor_noise_um=1.0..1.6"
SPEC_FORM = "METRIC<=BOUND:POINTS or METRIC>=BOUND:POINTS, e.g. 'fed_back_position_reduction_percent>=85:2'"


@dataclass(frozen=True)
class Variation:
    """A parameter drawn per student, uniformly in [low, high] (logarithmically for a
    parameter whose slider is logarithmic), in the parameter's own unit."""

    parameter: str
    low: float
    high: float


@dataclass(frozen=True)
class Spec:
    """A metric of ``Exercise.metrics`` held to a bound: ``relation`` "<=" or ">="; ``points``
    earned when it holds.  A yes/no metric counts as 1 (yes) or 0 (no)."""

    metric: str
    relation: str
    bound: float
    points: float

    @property
    def text(self) -> str:
        """As written on the command line (``metric<=bound``)."""
        return f"{self.metric}{self.relation}{self.bound:g}"


@dataclass(frozen=True)
class SpecResult:
    """One spec as graded: the metric's value on the student's variant and whether it holds."""

    metric: str
    relation: str
    bound: float
    points: float
    value: float | None           # None: not measured (the run stopped before it)
    passed: bool

    @property
    def earned(self) -> float:
        return self.points if self.passed else 0.0


@dataclass(frozen=True)
class Assignment:
    """What an instructor sets: the definition the store keeps (``as_json``/``from_json``)."""

    exercise: str
    title: str
    variations: tuple[Variation, ...]
    locked: tuple[str, ...]
    specs: tuple[Spec, ...]
    duration_s: float                       # simulated seconds each submission is graded on
    deadline: float | None = None           # s since the epoch (None: open)
    counts: str = "best"                    # "best" or "last" submission
    base: dict = field(default_factory=dict)   # values every student starts from (besides the drawn ones)

    @property
    def fixed(self) -> frozenset[str]:
        """Parameters a student cannot change: the locked and the drawn ones."""
        return frozenset(self.locked) | {v.parameter for v in self.variations}

    @property
    def points(self) -> float:
        return sum(spec.points for spec in self.specs)

    def as_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, data: dict) -> Assignment:
        return cls(exercise=data["exercise"], title=data["title"],
                   variations=tuple(Variation(**v) for v in data["variations"]), locked=tuple(data["locked"]),
                   specs=tuple(Spec(**s) for s in data["specs"]), duration_s=data["duration_s"],
                   deadline=data.get("deadline"), counts=data.get("counts", "best"), base=data.get("base", {}))

    def is_closed(self, now: float) -> bool:
        return self.deadline is not None and now > self.deadline


# -- reading an instructor's input (each failure one line naming what is valid) ---------------------
def _parameter(exercise: Exercise, name: str, option: str) -> Parameter:
    by_name = {p.name: p for p in exercise.parameters}
    if name not in by_name:
        raise ParameterError(f"{option} {name!r}: {exercise.name} has no such parameter: expected one of "
                             f"{', '.join(by_name)}")
    return by_name[name]


def parse_variation(exercise: Exercise, text: str) -> Variation:
    """``NAME=LOW..HIGH`` inside the parameter's valid range, LOW < HIGH."""
    name, sep, span = text.partition("=")
    low_text, dots, high_text = span.partition("..")
    if not (sep and dots):
        raise ParameterError(f"--vary {text!r} is not {VARY_FORM}")
    parameter = _parameter(exercise, name.strip(), "--vary")
    if parameter.choices:
        raise ParameterError(f"--vary {text!r}: {parameter.name} is a choice ({parameter.valid_range()}), "
                             "not a number to draw")
    low, high = parameter.parse(low_text.strip()), parameter.parse(high_text.strip())
    if not low < high:
        raise ParameterError(f"--vary {text!r}: LOW must be below HIGH, both in {parameter.valid_range()}")
    return Variation(parameter.name, float(low), float(high))


def parse_spec(text: str) -> Spec:
    """``METRIC<=BOUND:POINTS`` (or ``>=``); the metric is checked against the exercise by ``check_specs``."""
    match = re.fullmatch(r"\s*([A-Za-z_][A-Za-z0-9_]*)\s*(<=|>=)\s*([^:\s]+)\s*:\s*(\S+)\s*", text)
    if match is None:
        raise ParameterError(f"--spec {text!r} is not {SPEC_FORM}")
    metric, relation, bound_text, points_text = match.groups()
    try:
        bound, points = float(bound_text), float(points_text)
    except ValueError:
        raise ParameterError(f"--spec {text!r}: BOUND and POINTS must be numbers ({SPEC_FORM})") from None
    if not math.isfinite(bound) or not (math.isfinite(points) and 0 < points <= 1000):
        raise ParameterError(f"--spec {text!r}: BOUND must be finite and POINTS in 0 ... 1000 (above 0)")
    return Spec(metric, relation, bound, points)


def gradable(value) -> bool:
    """A metric a spec can hold to a bound: a number or a yes/no (None: a stopped run's)."""
    return value is None or isinstance(value, (bool, np.bool_)) or (
        isinstance(value, (int, float, np.number)) and not isinstance(value, str))


def check_specs(specs: tuple[Spec, ...], metrics: dict, exercise: Exercise) -> None:
    """Every spec names a number the exercise measures (``metrics``: one run on the defaults)."""
    if not specs:
        raise ParameterError(f"an assignment needs at least one --spec ({SPEC_FORM})")
    numbers = [name for name, value in metrics.items() if gradable(value)]
    for spec in specs:
        if spec.metric not in numbers:
            raise ParameterError(f"--spec {spec.text!r}: {exercise.name} measures no number {spec.metric!r}: "
                                 f"expected one of {', '.join(numbers)}")


def parse_deadline(text: str | None) -> float | None:
    """An ISO 8601 date and time (``2026-12-01T23:59``, local time unless it names its zone)."""
    if text is None:
        return None
    try:
        moment = datetime.fromisoformat(text.strip())
    except ValueError:
        raise ParameterError(f"--deadline {text!r} is not a date and time: expected YYYY-MM-DDTHH:MM "
                             "(e.g. 2026-12-01T23:59, or with a zone: 2026-12-01T23:59+01:00)") from None
    return moment.timestamp()


def shown_deadline(deadline: float | None) -> str:
    if deadline is None:
        return "none"
    return datetime.fromtimestamp(deadline, UTC).strftime("%Y-%m-%d %H:%M UTC")


def check_student(text) -> str:
    """A student's name or id as given (1 ... 64 printable characters, spaces at the ends dropped)."""
    student = str(text or "").strip()
    if not 0 < len(student) <= STUDENT_ID_CHARACTERS or not student.isprintable():
        raise ParameterError(f"student {student[:20]!r}: expected a name or student id of 1 ... "
                             f"{STUDENT_ID_CHARACTERS} printable characters")
    return student


def new_assignment(exercise_name: str, title: str | None, varied: list[str], locked: list[str], specs: list[str],
                   deadline: str | None = None, counts: str = "best", duration: float | None = None,
                   base: dict | None = None, metrics_of_defaults: dict | None = None) -> Assignment:
    """An assignment from the instructor's options, every part checked (``ParameterError``: one
    line naming the problem and the valid range).  ``metrics_of_defaults``: one run's metrics, to
    check the specs' names (computed here when not given)."""
    exercise = get(exercise_name)
    variations = tuple(parse_variation(exercise, text) for text in varied)
    if len({v.parameter for v in variations}) != len(variations):
        raise ParameterError("--vary names a parameter twice: each parameter is drawn from one range")
    locked_names = tuple(dict.fromkeys(_parameter(exercise, name.strip(), "--lock").name for name in locked))
    if counts not in COUNTS:
        raise ParameterError(f"--counts {counts!r}: expected one of {', '.join(COUNTS)}")
    low, high = exercise.min_duration_s, 60.0
    duration_s = exercise.default_duration_s if duration is None else float(duration)
    if not (math.isfinite(duration_s) and low <= duration_s <= high):
        raise ParameterError(f"--duration {duration!r} is out of range: expected {low:g} ... {high:g} s")
    base_values = exercise.resolve(dict(base or {}))
    base_values.pop("data", None)
    parsed = tuple(parse_spec(text) for text in specs)
    check_specs(parsed, metrics_of_defaults if metrics_of_defaults is not None
                else exercise.metrics(base_values, duration_s), exercise)
    return Assignment(exercise=exercise.name, title=(title or exercise.title).strip()[:120] or exercise.title,
                      variations=variations, locked=locked_names, specs=parsed, duration_s=duration_s,
                      deadline=parse_deadline(deadline), counts=counts,
                      base={k: (v.item() if hasattr(v, "item") else v) for k, v in (base or {}).items()})


# -- one student's plant ------------------------------------------------------------------------
def _draw_seed(code: str, student: str) -> int:
    """The seed of a student's variant: SHA-256 of the assignment code and the student's id."""
    digest = hashlib.sha256(f"{code}\n{student}".encode()).digest()
    return int.from_bytes(digest[:8], "big")


def variant(assignment: Assignment, code: str, student: str) -> dict:
    """The student's drawn parameter values (name -> value in the parameter's unit), the same
    for the same assignment code and student id, every time and on every machine."""
    exercise = get(assignment.exercise)
    by_name = {p.name: p for p in exercise.parameters}
    generator = np.random.Generator(np.random.PCG64(_draw_seed(code, check_student(student))))
    drawn = {}
    for variation in assignment.variations:
        parameter, fraction = by_name[variation.parameter], generator.random()
        if parameter.log and variation.low > 0:
            # log-uniform: value = low · (high/low)^u
            value = variation.low * (variation.high / variation.low) ** fraction
        else:
            value = variation.low + fraction * (variation.high - variation.low)   # uniform: low + u (high − low)
        value = round(value) if parameter.integer else float(f"{value:.{SIGNIFICANT_DIGITS}g}")
        drawn[parameter.name] = min(max(value, variation.low), variation.high)
    return drawn


def student_values(assignment: Assignment, code: str, student: str, settings: dict) -> dict:
    """The values a submission is graded on: the assignment's base values, the student's settings
    (``ParameterError`` for a locked or drawn one) and the student's variant, all checked."""
    exercise = get(assignment.exercise)
    for name in settings:
        if name in assignment.fixed:
            raise ParameterError(f"{name} is fixed in this assignment: expected changes to "
                                 f"{', '.join(changeable(assignment)) or 'nothing'}")
    return exercise.resolve({**assignment.base, **settings, **variant(assignment, code, student)})


def changeable(assignment: Assignment) -> list[str]:
    """The parameters a student may change."""
    return [p.name for p in get(assignment.exercise).parameters if p.name not in assignment.fixed]


# -- grading ------------------------------------------------------------------------------------
def _as_number(value) -> float | None:
    if value is None:
        return None
    number = float(value)
    return number if math.isfinite(number) else None


def grade(specs: tuple[Spec, ...], metrics: dict) -> list[SpecResult]:
    """Each spec held to ``metrics`` (computed on the server); a metric a stopped run left
    unmeasured (None, NaN) fails its spec."""
    results = []
    for spec in specs:
        value = _as_number(metrics.get(spec.metric))
        passed = value is not None and (value <= spec.bound if spec.relation == "<=" else value >= spec.bound)
        results.append(SpecResult(spec.metric, spec.relation, spec.bound, spec.points, value, passed))
    return results


def grade_submission(assignment: Assignment, code: str, student: str,
                     settings: dict) -> tuple[dict, list[SpecResult]]:
    """(the values graded, each spec's result): the exercise's metrics recomputed headless on
    the student's variant with the student's settings."""
    values = student_values(assignment, code, student, settings)
    metrics = get(assignment.exercise).metrics(values, assignment.duration_s)
    return values, grade(assignment.specs, metrics)


def score(results: list[SpecResult]) -> float:
    return sum(result.earned for result in results)


def counted_score(assignment: Assignment, scores: list[float]) -> float | None:
    """The score that counts of a student's submissions (oldest first): the best or the last;
    None when there is none."""
    if not scores:
        return None
    return max(scores) if assignment.counts == "best" else scores[-1]
