"""``python -m app run NAME --filter-history FROM:TO [--branch SETTINGS@SAMPLE] [--json]``: the
filter's history for samples FROM ≤ k < TO (x̂⁻, P⁻, K, innovation, S, x̂⁺, P⁺, the true state and
the measurement per sample, NEES/NIS over them with 95 % χ² bounds), and optionally a branch: the
filter rerun from one sample with Q and R scaled, on the same measurements
(``lab_modules.estimators.filter_history``).

Bad input raises ``ParameterError`` (one line, exit 2)."""

from __future__ import annotations

import json
import math

import numpy as np

from lab_modules.estimators.filter_consistency import ConsistencyTest, consistency
from lab_modules.estimators.filter_history import ARRAY_FIELDS, CAPACITY, FilterHistory, branch
from lab_modules.parameters import ParameterError

#: The branch's settings and what they scale.
BRANCH_SETTINGS = {"q_scale": "Q", "r_scale": "R"}
CHUNK = 1000                      # samples per advance (as the browser's frames, about)


def sample_range(text: str) -> tuple[int, int]:
    """``FROM:TO`` as sample numbers, FROM < TO, at most ``CAPACITY`` samples."""
    first, sep, last = text.partition(":")
    try:
        first_sample, last_sample = int(first), int(last)
    except ValueError:
        raise ParameterError(f"--filter-history {text!r} is not FROM:TO (sample numbers, e.g. 2000:2100)") from None
    if not sep or not 0 <= first_sample < last_sample:
        raise ParameterError(f"--filter-history {text!r}: expected 0 <= FROM < TO (samples FROM ... TO-1)")
    if last_sample - first_sample > CAPACITY:
        raise ParameterError(f"--filter-history {text!r}: at most {CAPACITY} samples are kept, "
                             f"asked for {last_sample - first_sample}")
    return first_sample, last_sample


def branch_settings(text: str, sample_time_s: float) -> tuple[dict[str, float], int]:
    """``q_scale=10,r_scale=0.5@SAMPLE`` (or ``@t=SECONDS``) as (scales, sample number)."""
    settings, at, where = text.partition("@")
    if not at:
        raise ParameterError(f"--branch {text!r} is not SETTINGS@SAMPLE (e.g. q_scale=10@2050 or q_scale=10@t=0.1)")
    scales = {}
    for pair in settings.split(","):
        name, sep, value = pair.partition("=")
        name = name.strip()
        if not sep or name not in BRANCH_SETTINGS:
            raise ParameterError(f"--branch: {pair.strip()!r} is not one of {', '.join(BRANCH_SETTINGS)}=FACTOR")
        try:
            scales[name] = float(value)
        except ValueError:
            raise ParameterError(f"--branch: {name}={value.strip()!r} is not a number") from None
        if not (math.isfinite(scales[name]) and 1e-6 <= scales[name] <= 1e6):
            raise ParameterError(f"--branch: {name}={value.strip()} is out of range: expected 1e-06 ... 1e+06")
    seconds = where.strip().startswith("t=")
    try:
        point = float(where.strip()[2:]) if seconds else int(where)
    except ValueError:
        raise ParameterError(f"--branch: {where!r} is not a sample number or t=SECONDS") from None
    return scales, round(point / sample_time_s) if seconds else point


def recorded_history(simulation, last_sample: int) -> FilterHistory:
    """The simulation run to ``last_sample`` (exclusive) and its filter's kept history."""
    advanced = 0
    while advanced < last_sample:
        done = len(simulation.advance(min(CHUNK, last_sample - advanced)))
        advanced += done
        if done == 0 or simulation.status_message():
            break
    history = simulation.filter_tape().history()
    end = 0 if history is None else history.first_sample + len(history)
    if end < last_sample:
        raise ParameterError(f"the simulation stopped at sample {end}, before {last_sample}: "
                             f"{simulation.status_message() or 'no samples'}")
    return history


def samples(history: FilterHistory) -> list[dict]:
    return [history.sample(row) for row in range(len(history))]


def test_dict(result: ConsistencyTest) -> dict:
    return {"mean": result.mean, "dof": result.dof, "samples": result.samples,
            "independent_samples": result.independent_samples, "lower_95": result.lower,
            "upper_95": result.upper, "inside": result.inside, "verdict": result.verdict}


def window(history: FilterHistory) -> dict:
    """The window's samples and its NEES and NIS."""
    return {"samples": samples(history), **{r.name: test_dict(r) for r in consistency(history)}}


def report(exercise, values: dict, span: str, branch_text: str | None) -> dict:
    """The filter's history for ``span`` (``FROM:TO``) and the branch ``branch_text``, as data."""
    first_sample, last_sample = sample_range(span)
    simulation = exercise.simulation(values)
    if not callable(getattr(simulation, "filter_tape", None)) or simulation.filter_tape() is None:
        raise ParameterError(f"exercise {exercise.name!r} has no sampled Kalman filter to replay at these settings "
                             "(--filter-history works for the exercises whose simulation offers filter_tape)")
    scales, branch_sample = branch_settings(branch_text, simulation.sample_time_s) if branch_text else ({}, None)
    if branch_sample is not None and not first_sample <= branch_sample < last_sample:
        raise ParameterError(f"--branch: sample {branch_sample} is outside --filter-history "
                             f"{first_sample}:{last_sample}")
    history = recorded_history(simulation, last_sample)
    model = history.model
    shown = history.rows(history.index_of(first_sample), history.index_of(last_sample - 1) + 1)
    result = {"filter": {"title": model.title, "sample_time_s": model.sample_time_s, "states": model.states,
                         "measurements": model.measurements, "Phi": model.Phi, "Gamma": model.Gamma,
                         "H": model.H, "Q": model.Q, "R": model.R},
              "fields": ARRAY_FIELDS, "history": window(shown)}
    if branch_sample is not None:
        tuned = model.scaled(scales.get("q_scale", 1.0), scales.get("r_scale", 1.0))
        rerun = branch(history, history.index_of(branch_sample), tuned)
        rerun = rerun.rows(0, rerun.index_of(last_sample - 1) + 1)
        result["branch"] = {"from_sample": branch_sample, **scales, "Q": tuned.Q, "R": tuned.R, **window(rerun)}
    return result


def text(result: dict) -> str:
    """A line per sample (time, innovations, NIS and the first state's estimate) and the tests."""
    lines = [result["filter"]["title"]]
    for part in ("history", "branch"):
        if part not in result:
            continue
        lines.append(f"{part}: sample, t [s], innovation ν, x̂⁺ [{result['filter']['states'][0][1]}], "
                     f"±σ⁺ of {result['filter']['states'][0][0]}")
        for s in result[part]["samples"]:
            lines.append(f"  {s['sample']} {s['time_s']:.6f} {' '.join(f'{v:.6g}' for v in s['innovation'])} "
                         f"{s['x_post'][0]:.6g} {math.sqrt(max(s['P_post'][0, 0], 0.0)):.6g}")
        for name in ("NEES", "NIS"):
            r = result[part][name]
            lines.append(f"  {name} {r['mean']:.4g} in [{r['lower_95']:.4g}, {r['upper_95']:.4g}] "
                         f"({r['independent_samples']} independent samples): {r['verdict']}")
    return "\n".join(lines)


def plain(value):
    """Arrays as nested lists (``headless.jsonable`` then makes numbers plain and NaN a string)."""
    if isinstance(value, dict):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    return value.tolist() if isinstance(value, np.ndarray) else value


def dumps(result: dict, jsonable) -> str:
    return json.dumps(jsonable(plain(result)), indent=1, ensure_ascii=False)
