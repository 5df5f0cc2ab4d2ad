"""Command line of the lab.

    python -m app [--host H] [--port P] [--exercise NAME] [--data-dir DIR | --database URL]
                  [--token T | --token-file F]
                  [--max-tabs N] [--allow-origin URL ...] [--trusted-proxy A ...]
                                               start the browser lab (default; also ``serve``)
    python -m app serve --workers N [same options] [--worker-ports FIRST]   N lab processes behind HAProxy
    python -m app haproxy-config --backend HOST:PORT ...    HAProxy configuration for several machines
    python -m app list [--json]                exercises and their parameters
    python -m app run NAME [--set N=V ...] [--duration S] [--seed N] [--data FILE] [--json]
    python -m app run --code KN-7Q3M-X9TA-HPRW [--set N=V ...] [--json]   a saved experiment, headless
    python -m app run NAME --filter-history FROM:TO [--branch q_scale=10@SAMPLE] [--json]
                                               the Kalman filter's history (and a branch), headless
    python -m app save NAME [--set N=V ...] [--data FILE]        save an experiment, print its code
    python -m app assignment create --exercise NAME --vary N=LOW..HIGH ... [--lock N ...]
                  --spec 'METRIC<=BOUND:POINTS' ... [--deadline T] [--counts best|last] [--json]
    python -m app assignment variant CODE --student ID [--json]      a student's drawn parameters
    python -m app assignment submit CODE --student ID [--set N=V ...] [--json]   graded headless
    python -m app grades CODE [CODE ...] --csv [--lms canvas|moodle]  the gradebook for the LMS
        (run, save, assignment and grades take --data-dir DIR or --database postgresql://...)
    python -m app bench [--json] [--browser]   throughput benchmark; --browser: slider-to-readout latency
    python -m app reproduce [--json] [--quick] [--html DIR] [--exercise NAME ...]
                                               every paper claim measured; exit 1 if one fails
    python -m app bench --clients N [--workers W] [--mix]   headless tabs: scope updates/s, bytes/s, CPU; capacity
    python -m app bench --analysis [NAME ...]   CPU of a slider move and of opening each panel, per exercise

Bad input (unknown exercise or parameter, non-numbers, NaN, out of range, a
busy port, an unknown code) exits with status 2 and one line naming the
problem and the valid range.  ``run`` exits with status 1 (one line, after
the output) if a metric is not finite and no stop status explains it.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

from app.commands import headless
from app.infra import access
from app.infra.database import DATABASE_VARIABLE
from lab_modules.parameters import ParameterError

USAGE_ERROR = 2


def _serve_options(parser: argparse.ArgumentParser, defaults: bool) -> None:
    """The server's options, on the main parser (``python -m app --port P``) and on ``serve``
    (``python -m app serve --port P``; SUPPRESS keeps the subparser from resetting the first)."""
    def default(value):
        return value if defaults else argparse.SUPPRESS
    parser.add_argument("--host", default=default("127.0.0.1"),
                        help="address to serve on (default 127.0.0.1; 0.0.0.0: the whole network, with a token)")
    parser.add_argument("--port", default=default("8080"), help="port to serve on, 1 ... 65535 (default 8080)")
    parser.add_argument("--exercise", default=default("kalman_noise"),
                        help="exercise a new tab opens on (default kalman_noise; tabs can switch)")
    parser.add_argument("--data-dir", default=default(None), metavar="DIR",
                        help="where saved experiments live (default ~/.local/share/amb-lab)")
    _database_option(parser, default(None))
    parser.add_argument("--token", default=default(None),
                        help="class token asked of every new tab when not on loopback (default: generated; "
                             "the process list shows it to every user: prefer --token-file or "
                             f"${access.TOKEN_VARIABLE})")
    parser.add_argument("--token-file", default=default(None), metavar="FILE",
                        help="read the class token from the first line of FILE")
    parser.add_argument("--instructor-token-file", default=default(None), metavar="FILE",
                        help="read the instructor page's token from the first line of FILE (default: "
                             f"${access.INSTRUCTOR_TOKEN_VARIABLE}, else generated and printed at start)")
    parser.add_argument("--trusted-proxy", action="append", default=default([]), metavar="ADDRESS",
                        help="a proxy whose X-Forwarded-For names the student's address (repeatable; "
                             "loopback is always trusted), e.g. the balancer in front of several machines")
    parser.add_argument("--max-tabs", default=default(str(access.TABS_PER_PROCESS)), metavar="N",
                        help=f"tabs one lab process gives a lab (default {access.TABS_PER_PROCESS}, what one core "
                             "streams at full rate); further tabs wait at a 'the lab is full' note")
    parser.add_argument("--allow-origin", action="append", default=default([]), metavar="URL",
                        help="a web origin besides the lab's own address that may open tabs (repeatable), "
                             "e.g. https://lab.example.org behind a proxy")


def _database_option(parser: argparse.ArgumentParser, default) -> None:
    parser.add_argument("--database", default=default, metavar="URL",
                        help="keep experiments, assignments and submissions in PostgreSQL, shared by every lab "
                             "process on every machine: postgresql://USER:PASSWORD@HOST:PORT/DB (default: "
                             f"${DATABASE_VARIABLE}, else SQLite in --data-dir)")


def _store_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--data-dir", default=None, metavar="DIR", help="where saved experiments live")
    _database_option(parser, None)
    parser.add_argument("--json", action="store_true", help="print JSON")


def _assignment_parsers(sub) -> None:
    assignment = sub.add_parser("assignment", help="create an assignment, draw a student's variant, submit")
    steps = assignment.add_subparsers(dest="step", required=True)
    create = steps.add_parser("create", help="a new assignment: prints its code and student link")
    create.add_argument("--exercise", required=True, help="the exercise (python -m app list)")
    create.add_argument("--title", default=None, help="shown to students and in the gradebook")
    create.add_argument("--vary", action="append", default=[], metavar="NAME=LOW..HIGH",
                        help="a parameter drawn per student in [LOW, HIGH] (repeatable; locked for the student)")
    create.add_argument("--lock", action="append", default=[], metavar="NAME",
                        help="a parameter the student may not change (repeatable)")
    create.add_argument("--spec", action="append", default=[], metavar="METRIC<=BOUND:POINTS",
                        help="a metric to meet (<= or >=) and its points (repeatable; at least one)")
    create.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="a value every student starts from (repeatable)")
    create.add_argument("--deadline", default=None, metavar="YYYY-MM-DDTHH:MM",
                        help="no submissions after this (local time unless a zone is given)")
    create.add_argument("--counts", default="best", help="which submission counts: best (default) or last")
    create.add_argument("--duration", default=None, type=float, metavar="S",
                        help="simulated seconds each submission is graded on (default: the exercise's)")
    create.add_argument("--url", default="http://127.0.0.1:8080", metavar="URL",
                        help="the lab's address, for the student link (default http://127.0.0.1:8080)")
    variant = steps.add_parser("variant", help="a student's drawn parameters")
    submit = steps.add_parser("submit", help="grade a student's settings (recomputed headless) and keep them")
    for parser in (variant, submit):
        parser.add_argument("code", help="the assignment's code")
        parser.add_argument("--student", required=True, help="the student's name or id")
    submit.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                        help="a setting of the student's design (repeatable)")
    for parser in (create, variant, submit):
        _store_options(parser)
    grades = sub.add_parser("grades", help="the gradebook of one or more assignments, for the LMS")
    grades.add_argument("codes", nargs="+", metavar="CODE", help="assignment code(s): one column each")
    grades.add_argument("--csv", action="store_true", help="CSV as the LMS imports it (default: tab-separated)")
    grades.add_argument("--lms", default="canvas", choices=("canvas", "moodle"),
                        help="column layout: canvas (default) or moodle")
    _store_options(grades)


def _parser() -> argparse.ArgumentParser:
    # no abbreviations: the main parser would read a subcommand's --data as an ambiguous --data-dir/--database
    parser = argparse.ArgumentParser(prog="python -m app", description="AMB estimation lab", allow_abbrev=False)
    _serve_options(parser, defaults=True)
    sub = parser.add_subparsers(dest="command")
    serve = sub.add_parser("serve", help="start the browser lab (the default); --workers N: N processes "
                                         "behind HAProxy")
    _serve_options(serve, defaults=False)
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
    run.add_argument("exercise", nargs="?", help="exercise name (or --code)")
    run.add_argument("--code", default=None, help="run a saved experiment (e.g. KN-7Q3M-X9TA-HPRW)")
    run.add_argument("--data-dir", default=None, metavar="DIR", help="where saved experiments live")
    _database_option(run, None)
    run.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                     help="override a parameter (repeatable)")
    run.add_argument("--duration", default=None, help="simulated seconds (default: the exercise's)")
    run.add_argument("--seed", default=None, help="random seed (same as --set seed=N)")
    run.add_argument("--data", default=None, metavar="FILE",
                     help="data file for exercises that take one (e.g. a recording CSV)")
    run.add_argument("--json", action="store_true", help="print JSON")
    run.add_argument("--filter-history", default=None, metavar="FROM:TO",
                     help="instead of the metrics: the Kalman filter at samples FROM ... TO-1 (priors, gains, "
                          "innovations, posteriors, true state, measurement; NEES/NIS with 95%% bounds)")
    run.add_argument("--branch", default=None, metavar="SETTINGS@SAMPLE",
                     help="with --filter-history: the filter rerun from SAMPLE (or t=SECONDS) with Q, R scaled "
                          "on the same measurements, e.g. q_scale=10@2050 or q_scale=10,r_scale=0.5@t=0.1")
    save = sub.add_parser("save", help="save an experiment (e.g. an instructor's preset) and print its code")
    save.add_argument("exercise")
    save.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                      help="a parameter value (repeatable; the rest keep their defaults)")
    save.add_argument("--data", default=None, metavar="FILE", help="a recording for exercises that take one")
    save.add_argument("--data-dir", default=None, metavar="DIR", help="where saved experiments live")
    _database_option(save, None)
    _assignment_parsers(sub)
    bench = sub.add_parser("bench", help="closed-loop throughput benchmark")
    bench.add_argument("--json", action="store_true", help="print JSON")
    bench.add_argument("--seconds", default="2.0", help="simulated seconds per measurement (0.1 ... 60)")
    bench.add_argument("--browser", action="store_true",
                       help="instead: slider-to-readout latency in headless Chromium (needs the test extras)")
    reproduce = sub.add_parser(
        "reproduce", help="measure every exercise's paper claims and print paper vs lab",
        description="Measure every exercise's paper claims (the `claims` of each exercise file) and print "
                    "paper vs lab with the range the lab holds itself to. Exit status 1 if a claim fails. "
                    "Default: each claim on seeds 0 to 4 (it must hold on all; exercises without a seed "
                    "run once). --quick: seed 0 only, each claim at its own settings and run length, as the "
                    "test suite checks it (under 3 minutes on 2 cores).")
    reproduce.add_argument("--json", action="store_true", help="print JSON")
    reproduce.add_argument("--quick", action="store_true",
                           help="seed 0 only (default: seeds 0-4; a claim must hold on each)")
    reproduce.add_argument("--html", default=None, metavar="DIR",
                           help="also write DIR/index.html: the table and the figures behind each exercise's "
                                "claims (PNG embedded)")
    reproduce.add_argument("--exercise", action="append", default=[], metavar="NAME", dest="only",
                           help="only this exercise (repeatable; default: all)")
    bench.add_argument("--clients", type=int, default=None, metavar="N",
                       help="instead: N headless websocket tabs against a started server (scope updates/s, "
                            "bytes/s, server CPU per tab; capacity)")
    bench.add_argument("--workers", type=int, default=1, metavar="W",
                       help="with --clients: lab processes behind HAProxy (default 1: one process, no HAProxy)")
    bench.add_argument("--steps", type=int, default=4, help="with --clients: ramp up in this many steps")
    bench.add_argument("--window", type=float, default=8.0, help="with --clients: seconds measured per step")
    bench.add_argument("--bench-port", type=int, default=8140,
                       help="with --clients: loopback port of the server (workers: the next ports)")
    bench.add_argument("--breakdown", action="store_true", help="with --clients: bytes by message kind")
    bench.add_argument("--slider-every", type=int, default=3, metavar="K",
                       help="with --clients: a tab moves a slider with every K-th camera message (every ~3 s); "
                            "0: never (streaming cost only)")
    bench.add_argument("--mix", action="store_true",
                       help="with --clients: spread the tabs over every exercise and over the Scope, Pole map and "
                            "Analysis tabs (default: all on --exercise, Scope shown)")
    bench.add_argument("--analysis", nargs="*", default=None, metavar="NAME",
                       help="instead: CPU of a slider move with the Scope shown, of opening each panel and of "
                            "the first open, per exercise (default: every exercise)")
    bench.add_argument("--runs", type=int, default=1, metavar="K",
                       help="with --clients: the whole ramp K times (1 ... 10), each on a fresh server; "
                            "prints in how many runs each step held")
    bench.add_argument("--all-steps", action="store_true",
                       help="with --clients: go on after a step below the target (default: stop there)")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        if args.command == "list":
            return headless.command_list(args.json)
        if args.command == "run":
            return headless.command_run(args)
        if args.command == "reproduce":
            from app.commands.reproduce import main as reproduce_main
            return reproduce_main(args.json, args.quick, args.html, args.only)
        if args.command == "save":
            return headless.command_save(args)
        if args.command in ("assignment", "grades"):
            from app.commands import assignments
            command = args.command if args.command == "grades" else args.step
            return getattr(assignments, f"command_{command}")(args)
        if args.command == "bench" and args.browser:
            from app.commands.browser_bench import main as browser_bench_main
            with tempfile.TemporaryDirectory() as scratch:
                return browser_bench_main(args.json, Path(scratch) / "server.log")
        if args.command == "haproxy-config":
            from app.hall import check_port, haproxy_config, parse_backend
            backends = [parse_backend(b) for b in args.backend]
            print(haproxy_config(args.bind_host, check_port(args.bind_port), backends,
                                 note="\n# Start the lab on every backend with the same token (--token-file), "
                                      "--allow-origin http://THIS_BALANCER and --trusted-proxy THIS_BALANCER;"
                                      "\n# run: haproxy -f THIS_FILE"), end="")
            return 0
        if args.command == "bench" and args.analysis is not None:
            from app.commands.analysis_bench import main as analysis_bench_main
            return analysis_bench_main(args.json, args.analysis)
        if args.command == "bench" and args.clients is not None:
            from app.commands.load_bench import main as load_bench_main
            return load_bench_main(args.clients, args.workers, args.steps, args.window, args.exercise,
                                   args.bench_port, args.breakdown, args.json, args.all_steps,
                                   args.slider_every, args.mix, args.runs)
        if args.command == "bench":
            from app.commands.bench import main as bench_main
            return bench_main(headless.bench_seconds(args.seconds), args.json)
    except ParameterError as error:
        print(f"error: {error}", file=sys.stderr)
        return USAGE_ERROR
    try:
        access.check_host(args.host)                      # before the (slow) server imports
        access.check_port(args.port)
        from app.server import Settings, serve
        settings = Settings.from_args(args)
        if args.command == "serve":
            from app.hall import check_workers, serve_hall
            workers = check_workers(args.workers)
            if workers > 1:
                return serve_hall(settings, workers, args.worker_ports, args.allow_origin or [])
    except ParameterError as error:
        print(f"error: {error}", file=sys.stderr)
        return USAGE_ERROR
    return serve(settings)
