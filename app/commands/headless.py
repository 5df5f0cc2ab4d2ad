"""Headless commands: ``list``, ``run`` (an exercise or a saved experiment) and ``save``.

Bad input raises ``ParameterError`` (the command line prints one line and exits 2);
``run`` returns ``NOT_FINITE`` (1) when a metric is not finite and no stop status
explains it."""

from __future__ import annotations

import json
import math
import os
import stat
import sys
from pathlib import Path

from app.infra.database import chosen_database, open_store
from app.infra.store import Store, StoreError
from lab_modules.exercises import get, registry
from lab_modules.parameters import ParameterError
from lab_modules.recordings import MAX_BYTES

NOT_FINITE = 1


def overrides_from(pairs: list[str], seed=None, exercise=None) -> dict:
    overrides = {}
    for pair in pairs:
        name, sep, value = pair.partition("=")
        if not sep or not name:
            raise ParameterError(f"--set {pair!r} is not NAME=VALUE")
        overrides[name.strip()] = value.strip()
    if seed is not None:
        if exercise is not None and not any(p.name == "seed" for p in exercise.parameters):
            raise ParameterError(f"--seed: exercise {exercise.name!r} draws no random numbers "
                                 "(it works on a recording); leave --seed out")
        overrides["seed"] = seed
    if "data" in overrides:
        raise ParameterError("'data' is not a parameter: use --data FILE")
    return overrides


MAX_DURATION_S = 60.0
BENCH_SECONDS = (0.1, 60.0)       # simulated seconds per benchmark measurement


def bench_seconds(text) -> float:
    """``bench --seconds`` in ``BENCH_SECONDS``, or ``ParameterError`` (NaN, negative or huge
    values would fail deep inside or ask for terabytes of trace)."""
    low, high = BENCH_SECONDS
    expected = f"expected {low:g} ... {high:g} s"
    try:
        value = float(text)
    except (TypeError, ValueError):
        raise ParameterError(f"--seconds={text!r} is not a number: {expected}") from None
    if not math.isfinite(value) or not low <= value <= high:
        raise ParameterError(f"--seconds={text!r} is out of range: {expected}")
    return value


def duration_from(text, default: float, minimum: float = 0.01) -> float:
    """``--duration`` in ``minimum`` ... ``MAX_DURATION_S`` seconds (the exercise's shortest run
    whose metrics are defined), or ``ParameterError``."""
    expected = f"expected {minimum:g} ... {MAX_DURATION_S:g} s"
    if text is None:
        return default
    try:
        value = float(text)
    except ValueError:
        raise ParameterError(f"--duration={text!r} is not a number: {expected}") from None
    if not math.isfinite(value):
        raise ParameterError(f"--duration={text!r} is not finite: {expected}")
    if not minimum <= value <= MAX_DURATION_S:
        raise ParameterError(f"--duration={text!r} is out of range: {expected}")
    return value


def jsonable(value):
    """Plain Python numbers for json (numpy scalars, non-finite floats as strings)."""
    if isinstance(value, dict):
        return {k: jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if hasattr(value, "item"):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return value


def command_list(as_json: bool) -> int:
    exercises = [{"name": e.name, "title": e.title, "worksheet": f"static/worksheets/{e.worksheet}",
                  "parameters": [p.describe() for p in e.parameters]} for e in registry().values()]
    if as_json:
        print(json.dumps(jsonable(exercises), indent=2, ensure_ascii=False))
    else:
        for e in exercises:
            print(f"{e['name']}: {e['title']}")
            for p in e["parameters"]:
                rng = ", ".join(p["choices"]) if "choices" in p else f"{p['min']:g} ... {p['max']:g}"
                print(f"  {p['name']:<24} default {p['default']!s:<12} [{rng}] {p['unit']}")
    return 0


def read_data_file(exercise, path) -> tuple[str, bytes] | None:
    """``--data FILE`` as (name, bytes), reading at most ``MAX_BYTES`` (+1 to tell a larger file)."""
    if path is None:
        return None
    if exercise.data_description is None:
        raise ParameterError(f"exercise {exercise.name!r} takes no --data file")
    try:
        mode = os.stat(path).st_mode
        if stat.S_ISFIFO(mode) or stat.S_ISSOCK(mode):     # would wait for a writer that may never come
            raise ParameterError(f"--data {path!r} is a pipe or socket, not a file")
        with open(path, "rb") as handle:
            content = handle.read(MAX_BYTES + 1)
    except OSError as error:
        raise ParameterError(f"--data {path!r}: {error.strerror}") from None
    if len(content) > MAX_BYTES:
        raise ParameterError(f"--data {path!r}: larger than {MAX_BYTES / 1e6:.0f} MB, the largest file accepted")
    return Path(path).name, content


def open_store_of(args) -> Store:
    """The store of a headless command's ``--database`` or ``--data-dir``; ``ParameterError`` (exit 2)."""
    try:
        return open_store(chosen_database(args.database, os.environ), args.data_dir)
    except StoreError as error:
        raise ParameterError(str(error)) from None


def non_finite(metrics, path: str = "") -> list[str]:
    """Keys (``a.b.2``) of the metrics that are NaN or infinite."""
    if isinstance(metrics, dict):
        return [k for name, v in metrics.items() for k in non_finite(v, f"{path}{name}.")]
    if isinstance(metrics, (list, tuple)) or hasattr(metrics, "tolist"):
        items = metrics.tolist() if hasattr(metrics, "tolist") else metrics
        if not isinstance(items, list):
            return non_finite(items, path)
        return [k for i, v in enumerate(items) for k in non_finite(v, f"{path}{i}.")]
    if isinstance(metrics, (int, float)) and not isinstance(metrics, bool) and not math.isfinite(metrics):
        return [path.rstrip(".")]
    return []


def stop_statuses(metrics: dict) -> list[str]:
    """The metrics' stop statuses other than "ok" (a run that touched down or diverged)."""
    return [f"{name}: {value}" for name, value in metrics.items()
            if "status" in name and isinstance(value, str) and value != "ok"]


def command_run(args) -> int:
    saved = None
    if args.code is not None:
        try:
            saved = open_store_of(args).load(args.code)
        except StoreError as error:
            raise ParameterError(str(error)) from None
        if args.exercise is not None and args.exercise != saved.exercise:
            raise ParameterError(f"{saved.code} is an experiment of {saved.exercise!r}, not {args.exercise!r}")
    elif args.exercise is None:
        raise ParameterError("run: name an exercise (python -m app list) or give --code")
    exercise = get(saved.exercise if saved else args.exercise)
    overrides = {**(saved.parameters if saved else {}), **overrides_from(args.set, args.seed, exercise)}
    data_file = read_data_file(exercise, args.data)
    if data_file is None and saved is not None and saved.recording is not None:
        data_file = (saved.recording_name, saved.recording)
    data = exercise.load_data(*data_file) if data_file else None
    values = exercise.resolve({**overrides, "data": data})
    duration = duration_from(args.duration, exercise.default_duration_s, exercise.min_duration_s)
    shown = {name: value for name, value in values.items() if name != "data"}
    if data_file is not None:
        shown["data"] = args.data or data_file[0]
    if args.filter_history is not None or args.branch is not None:
        return filter_history(args, exercise, values, shown)
    result = {"exercise": exercise.name, "parameters": shown,
              "model": exercise.model(values), "metrics": exercise.metrics(values, duration)}
    if saved is not None:
        result["code"] = saved.code
    if args.json:
        print(json.dumps(jsonable(result), indent=2, ensure_ascii=False))
    else:
        for name, value in result["metrics"].items():
            print(f"{name}: {value}")
    bad = non_finite(result["metrics"])
    if bad and not stop_statuses(result["metrics"]):
        print(f"error: metric {bad[0]} is not finite" + (f" (and {len(bad) - 1} more)" if len(bad) > 1 else "")
              + " and no stop status explains it", file=sys.stderr)
        return NOT_FINITE
    return 0


def filter_history(args, exercise, values: dict, shown: dict) -> int:
    """``run --filter-history FROM:TO [--branch ...]``: the filter's history instead of the metrics."""
    from app.commands import filter_debug
    if args.filter_history is None:
        raise ParameterError("--branch needs --filter-history FROM:TO (the samples the branch is printed for)")
    result = {"exercise": exercise.name, "parameters": shown,
              **filter_debug.report(exercise, values, args.filter_history, args.branch)}
    print(filter_debug.dumps(result, jsonable) if args.json else filter_debug.text(result))
    return 0


def command_save(args) -> int:
    exercise = get(args.exercise)
    overrides = overrides_from(args.set, None, exercise)
    data_file = read_data_file(exercise, args.data)
    values = exercise.resolve({**overrides, "data": exercise.load_data(*data_file) if data_file else None})
    name, content = data_file or (None, None)
    try:
        code = open_store_of(args).save(exercise.name, values, name, content)
    except StoreError as error:
        raise ParameterError(str(error)) from None
    print(code)
    return 0
