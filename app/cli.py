"""Command line of the lab.

    python -m app [--host H] [--port P] [--exercise NAME]   start the browser lab (default)
    python -m app serve --workers N [--host H] [--port P]   N lab processes behind HAProxy
    python -m app haproxy-config --backend HOST:PORT ...    HAProxy configuration for several machines
    python -m app list [--json]                exercises and their parameters
    python -m app run NAME [--set N=V ...] [--duration S] [--seed N] [--data FILE] [--json]
    python -m app bench [--json] [--browser]   throughput benchmark; --browser: slider-to-readout latency
    python -m app bench --clients N [--workers W]   headless tabs: scope updates/s, bytes/s, CPU; capacity

Bad input (unknown exercise or parameter, non-numbers, NaN, out of range)
exits with status 2 and one line naming the problem and the valid range.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from pathlib import Path

from lab_modules.exercises import get, registry
from lab_modules.parameters import ParameterError

USAGE_ERROR = 2


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m app", description="AMB estimation lab")
    parser.add_argument("--host", default="127.0.0.1", help="address to serve on (default 127.0.0.1)")
    parser.add_argument("--port", type=int, default=8080, help="port to serve on (default 8080)")
    parser.add_argument("--exercise", default="kalman_noise",
                        help="exercise a new tab opens on (default kalman_noise; tabs can switch)")
    sub = parser.add_subparsers(dest="command")
    serve = sub.add_parser("serve", help="start the browser lab (the default); --workers N: N processes "
                                         "behind HAProxy")
    serve.add_argument("--host", default=argparse.SUPPRESS, help="address to serve on (default 127.0.0.1)")
    serve.add_argument("--port", type=int, default=argparse.SUPPRESS, help="port to serve on (default 8080)")
    serve.add_argument("--exercise", default=argparse.SUPPRESS, help="exercise a new tab opens on")
    serve.add_argument("--workers", type=int, default=None, metavar="N",
                       help="lab processes behind HAProxy (default: one per core; 1: one process, no HAProxy)")
    serve.add_argument("--worker-ports", type=int, default=None, metavar="FIRST",
                       help="the workers' loopback ports: FIRST, FIRST+1, ... (default: --port + 1)")
    balancer = sub.add_parser("haproxy-config", help="print an HAProxy configuration for lab processes "
                                                     "on several machines")
    balancer.add_argument("--backend", action="append", required=True, metavar="HOST:PORT",
                          help="a lab process or a machine's 'serve --workers' address (repeatable)")
    balancer.add_argument("--host", dest="bind_host", default="0.0.0.0",
                          help="address the balancer listens on (default 0.0.0.0)")
    balancer.add_argument("--port", dest="bind_port", type=int, default=8080,
                          help="port the balancer listens on (default 8080)")
    listing = sub.add_parser("list", help="list exercises and their parameters")
    listing.add_argument("--json", action="store_true", help="print JSON")
    run = sub.add_parser("run", help="run one exercise headless and print its metrics")
    run.add_argument("exercise")
    run.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                     help="override a parameter (repeatable)")
    run.add_argument("--duration", default=None, help="simulated seconds (default: the exercise's)")
    run.add_argument("--seed", default=None, help="random seed (same as --set seed=N)")
    run.add_argument("--data", default=None, metavar="FILE",
                     help="data file for exercises that take one (e.g. a recording CSV)")
    run.add_argument("--json", action="store_true", help="print JSON")
    bench = sub.add_parser("bench", help="closed-loop throughput benchmark")
    bench.add_argument("--json", action="store_true", help="print JSON")
    bench.add_argument("--seconds", type=float, default=2.0, help="simulated seconds per measurement")
    bench.add_argument("--browser", action="store_true",
                       help="instead: slider-to-readout latency in headless Chromium (needs the test extras)")
    bench.add_argument("--clients", type=int, default=None, metavar="N",
                       help="instead: N headless websocket tabs against a started server (scope updates/s, "
                            "bytes/s, server CPU per tab; capacity)")
    bench.add_argument("--workers", type=int, default=1, metavar="W",
                       help="with --clients: lab processes behind HAProxy (default 1: one process, no HAProxy)")
    bench.add_argument("--steps", type=int, default=4, help="with --clients: ramp up in this many steps")
    bench.add_argument("--window", type=float, default=8.0, help="with --clients: seconds measured per step")
    bench.add_argument("--bench-port", type=int, default=8109, help="with --clients: loopback port of the server")
    bench.add_argument("--breakdown", action="store_true", help="with --clients: bytes by message kind")
    bench.add_argument("--slider-every", type=int, default=3, metavar="K",
                       help="with --clients: a tab moves a slider with every K-th camera message (every ~3 s); "
                            "0: never (streaming cost only)")
    bench.add_argument("--all-steps", action="store_true",
                       help="with --clients: go on after a step below the target (default: stop there)")
    return parser


def _overrides(pairs: list[str], seed) -> dict:
    overrides = {}
    for pair in pairs:
        name, sep, value = pair.partition("=")
        if not sep or not name:
            raise ParameterError(f"--set {pair!r} is not NAME=VALUE")
        overrides[name.strip()] = value.strip()
    if seed is not None:
        overrides["seed"] = seed
    return overrides


def _duration(text, default: float) -> float:
    if text is None:
        return default
    try:
        value = float(text)
    except ValueError:
        raise ParameterError(f"--duration={text!r} is not a number: expected 0.01 ... 60 s") from None
    if not (math.isfinite(value) and 0.01 <= value <= 60.0):
        raise ParameterError(f"--duration={text!r} is out of range: expected 0.01 ... 60 s")
    return value


def _jsonable(value):
    """Plain Python numbers for json (numpy scalars, non-finite floats as strings)."""
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if hasattr(value, "item"):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return value


def command_list(as_json: bool) -> int:
    exercises = [{"name": e.name, "title": e.title, "worksheet": f"static/worksheets/{e.worksheet}",
                  "parameters": [p.describe() for p in e.parameters]} for e in registry().values()]
    if as_json:
        print(json.dumps(_jsonable(exercises), indent=2, ensure_ascii=False))
    else:
        for e in exercises:
            print(f"{e['name']}: {e['title']}")
            for p in e["parameters"]:
                rng = ", ".join(p["choices"]) if "choices" in p else f"{p['min']:g} ... {p['max']:g}"
                print(f"  {p['name']:<24} default {p['default']!s:<12} [{rng}] {p['unit']}")
    return 0


def _data(exercise, path):
    """The exercise's parsed data file (None: its shipped default)."""
    if path is None:
        return None
    if exercise.data_description is None:
        raise ParameterError(f"exercise {exercise.name!r} takes no --data file")
    try:
        content = Path(path).read_bytes()
    except OSError as error:
        raise ParameterError(f"--data {path!r}: {error.strerror}") from None
    return exercise.load_data(Path(path).name, content)


def command_run(args) -> int:
    exercise = get(args.exercise)
    overrides = _overrides(args.set, args.seed)
    if "data" in overrides:
        raise ParameterError("'data' is not a parameter: use --data FILE")
    values = exercise.resolve({**overrides, "data": _data(exercise, args.data)})
    duration = _duration(args.duration, exercise.default_duration_s)
    shown = {name: value for name, value in values.items() if name != "data"}
    if args.data is not None:
        shown["data"] = args.data
    result = {"exercise": exercise.name, "parameters": shown,
              "model": exercise.model(values), "metrics": exercise.metrics(values, duration)}
    if args.json:
        print(json.dumps(_jsonable(result), indent=2, ensure_ascii=False))
    else:
        for name, value in result["metrics"].items():
            print(f"{name}: {value}")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        if args.command == "list":
            return command_list(args.json)
        if args.command == "run":
            return command_run(args)
        if args.command == "bench" and args.browser:
            from app.browser_bench import main as browser_bench_main
            with tempfile.TemporaryDirectory() as scratch:
                return browser_bench_main(args.json, Path(scratch) / "server.log")
        if args.command == "haproxy-config":
            from app.hall import check_port, haproxy_config, parse_backend
            backends = [parse_backend(b) for b in args.backend]
            print(haproxy_config(args.bind_host, check_port(args.bind_port), backends,
                                 note="\n# Start the lab on every backend with the same --token; "
                                      "run: haproxy -f THIS_FILE"), end="")
            return 0
        if args.command == "serve" and (args.workers is None or args.workers != 1):
            from app.hall import check_port, check_workers, serve_hall
            get(args.exercise)
            workers = check_workers(args.workers)
            if workers > 1:
                return serve_hall(args.host, check_port(args.port), workers, args.exercise,
                                  args.worker_ports, forwarded=[])
        if args.command == "bench" and args.clients is not None:
            from app.load_bench import main as load_bench_main
            return load_bench_main(args.clients, args.workers, args.steps, args.window, args.exercise,
                                   args.bench_port, args.breakdown, args.json, args.all_steps,
                                   args.slider_every)
        if args.command == "bench":
            from app.bench import main as bench_main
            return bench_main(args.seconds, args.json)
    except ParameterError as error:
        print(f"error: {error}", file=sys.stderr)
        return USAGE_ERROR
    from app.server import serve
    try:
        get(args.exercise)
    except ParameterError as error:
        print(f"error: {error}", file=sys.stderr)
        return USAGE_ERROR
    serve(args.host, args.port, args.exercise)
    return 0
