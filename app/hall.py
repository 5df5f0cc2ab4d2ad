"""A lecture hall: several lab processes behind HAProxy.

``python -m app serve --workers N`` starts N lab processes (each the same
single-process lab as ``python -m app``, one simulation per tab) on loopback
ports and HAProxy in front of them on the public address, with a generated
configuration (``haproxy_config``): ``balance leastconn`` (a new tab goes to
the process with the fewest open tabs), a long ``timeout tunnel`` (a tab is
one websocket for the whole lesson), health checks on every process, and
retries with redispatch (a tab that connects while a process is down gets
another).  The supervisor restarts a process that exits (HAProxy routes
around it meanwhile), and on Ctrl-C or SIGTERM stops HAProxy and every
process; its children also get SIGTERM if the supervisor itself is killed.

``python -m app haproxy-config --backend HOST:PORT ...`` prints the same
configuration for lab processes on several machines behind one balancer.

A tab's lab lives in its websocket, so no stickiness is needed: the page and
its websocket may come from different processes.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from dataclasses import dataclass
from pathlib import Path

from app.infra.access import INSTRUCTOR_TOKEN_VARIABLE, TOKEN_VARIABLE, check_bindable, is_address
from app.infra.database import DATABASE_VARIABLE, open_store
from lab_modules.parameters import ParameterError

ROOT = Path(__file__).resolve().parent.parent
HAPROXY_MISSING = ("HAProxy is not installed: install it with 'apt-get install haproxy' "
                   "(Debian/Ubuntu), or serve one process with --workers 1")
WORKER_HEADER = "X-Lab-Worker"        # names the process that answered (tests, load bench)
MAX_WORKERS = 64
HEALTH_PATH, HEALTH_STATUS = "/lab-health-check", 404   # see haproxy_config
READY_TIMEOUT_S = 180.0               # a worker's first start compiles the loops (cached afterwards)
POLL_S = 0.5
RESTART_DELAYS_S = (1.0, 2.0, 5.0, 10.0, 30.0)   # after quick successive crashes
STABLE_AFTER_S = 30.0                 # a worker that ran this long restarts without delay
STOP_TIMEOUT_S = 10.0
PAGE_LOADS = 4                        # connections a process takes beyond its tabs: page loads, a "full" note
QUEUE_TIMEOUT_S = 5
#: What HAProxy answers when every process is at its cap (or none is up): one line, no quotes.
FULL_PAGE = ("<!doctype html><title>AMB estimation lab</title><h2>The lab is full</h2><p>Every place on the "
             "lab server is taken (or it is restarting). Try again in a minute, or ask your instructor.</p>")


def haproxy_config(bind_host: str, bind_port: int, backends: list[tuple[str, int]],
                   health_path: str = HEALTH_PATH, health_status: int = HEALTH_STATUS, note: str = "",
                   max_tabs: int | None = None) -> str:
    """An HAProxy configuration balancing lab tabs over ``backends`` (host, port); ``max_tabs``:
    each backend's ``--max-tabs``, capping its connections (tabs plus a few page loads) so that
    a full class spreads and the last students get the "lab is full" page."""
    cap = f" maxconn {max_tabs + PAGE_LOADS}" if max_tabs is not None else ""
    servers = "\n".join(f"    server lab{k + 1} {host}:{port}{cap}" for k, (host, port) in enumerate(backends))
    bind = f"[{bind_host}]" if ":" in bind_host else bind_host
    return f"""# AMB estimation lab: HAProxy in front of {len(backends)} lab process(es).{note}
global
    # no maxconn: HAProxy sizes it from the open-file limit

defaults
    mode http
    option redispatch 1                  # a retried connection may go to another process
    retries 3
    timeout connect 3s
    timeout client 30s
    timeout server 30s
    timeout http-request 10s
    timeout tunnel 4h                    # a tab is one websocket for the whole lesson
    timeout client-fin 5s
    timeout queue {QUEUE_TIMEOUT_S}s                      # every process at its maxconn: the page below, not a long wait
    http-error status 503 content-type "text/html; charset=utf-8" string "{FULL_PAGE}"

frontend lab
    bind {bind}:{bind_port}
    option forwardfor                    # the lab throttles wrong class tokens per client address
    default_backend labs

backend labs
    balance leastconn                    # a new tab goes to the process with the fewest open tabs
    # Health check: a small request the lab's event loop answers (HTTP/1.1 only), not the 800 kB page:
    # an unknown path, answered 404.
    option httpchk
    http-check send meth GET uri {health_path} ver HTTP/1.1 hdr Host lab
    http-check expect status {health_status}
    http-response set-header {WORKER_HEADER} %[srv_name]
    default-server check inter 1s fall 2 rise 2 observe layer4 error-limit 1 on-error mark-down
{servers}
"""


def parse_backend(text: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep or not host:
        raise ParameterError(f"--backend {text!r} is not HOST:PORT")
    return host.strip("[]"), check_port(port, "--backend port")


def check_port(value, name: str = "--port") -> int:
    try:
        port = int(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name}={value!r} is not a port number: expected 1 ... 65535") from None
    if not 1 <= port <= 65535:
        raise ParameterError(f"{name}={value!r} is out of range: expected 1 ... 65535")
    return port


def check_workers(value) -> int:
    if value is None:
        return os.cpu_count() or 1
    if not 1 <= value <= MAX_WORKERS:
        raise ParameterError(f"--workers={value} is out of range: expected 1 ... {MAX_WORKERS}")
    return value


def port_free(port: int, host: str = "127.0.0.1") -> bool:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError:
            return False
    return True


def _die_with_parent() -> None:
    """In a child before exec: SIGTERM when the supervisor dies (Linux), so no process is left
    even if the supervisor is killed outright."""
    with contextlib.suppress(OSError, AttributeError):
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)   # PR_SET_PDEATHSIG


@dataclass
class Worker:
    """One lab process on a loopback port."""

    index: int
    port: int
    command: list[str]
    environment: dict[str, str]
    process: subprocess.Popen | None = None
    started: float = 0.0
    crashes: int = 0                   # quick successive exits, for the restart delay
    restart_at: float | None = None
    exited_at: float | None = None     # set from an exit until the restarted process answers
    start_s: float | None = None       # how long its last start took until it answered [s]

    def start(self) -> None:
        self.process = subprocess.Popen(self.command, cwd=ROOT, env=self.environment, stdin=subprocess.DEVNULL,
                                        stdout=subprocess.DEVNULL, start_new_session=True,
                                        preexec_fn=_die_with_parent)  # noqa: PLW1509 (no threads here)
        self.started, self.restart_at = time.monotonic(), None

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/"


def worker_command(port: int, settings, allow_origins: list[str]) -> list[str]:
    """A worker: the single-process lab on a loopback port with the hall's settings (the class
    token goes in its environment: ``worker_environment``)."""
    command = [sys.executable, "-m", "app", "--host", "127.0.0.1", "--port", str(port),
               "--exercise", settings.exercise, "--max-tabs", str(settings.max_tabs)]
    for proxy in settings.trusted_proxies:
        command += ["--trusted-proxy", proxy]
    if settings.data_dir is not None:                 # one saved-experiments database for all workers
        command += ["--data-dir", str(settings.data_dir)]
    served = [] if is_address(settings.host) else [f"http://{settings.host}:{settings.port}"]   # the hall's name
    for origin in [*allow_origins, *served]:
        command += ["--allow-origin", origin]
    return command


def worker_environment(settings) -> dict[str, str]:
    """The workers' environment: the class token is passed on (a worker on loopback would otherwise
    ask none, and every tab reaches it through HAProxy from the network), in the environment, which
    only the instructor's user can read, not on the command line, which the process list shows to all."""
    environment = {name: value for name, value in os.environ.items() if name != TOKEN_VARIABLE}
    if settings.token is not None:
        environment[TOKEN_VARIABLE] = settings.token
    environment[INSTRUCTOR_TOKEN_VARIABLE] = settings.instructor_token   # one instructor token for the hall
    if settings.database is not None:                 # one PostgreSQL database for all (its URL may hold a password)
        environment[DATABASE_VARIABLE] = settings.database
    return environment


def _ready(url: str) -> bool:
    try:
        urllib.request.urlopen(url, timeout=2).close()
        return True
    except OSError:
        return False


def _stop(processes: list[subprocess.Popen]) -> None:
    """Stop processes: SIGTERM (HAProxy: hard stop, no waiting for open websockets), SIGKILL after
    a timeout."""
    for process in processes:
        if process.poll() is None:
            with contextlib.suppress(ProcessLookupError):
                process.terminate()
    deadline = time.monotonic() + STOP_TIMEOUT_S
    for process in processes:
        try:
            process.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


class _Stop(Exception):
    pass


def _raise_stop(signum, _frame) -> None:
    raise _Stop(signal.Signals(signum).name)


def serve_hall(settings, workers: int, first_worker_port: int | None, allow_origins: list[str]) -> int:
    """Serve the lab (``settings``: ``app.server.Settings``) with ``workers`` processes behind
    HAProxy until Ctrl-C or SIGTERM."""
    from app.infra.store import StoreError
    from app.server import shown_url
    haproxy = shutil.which("haproxy")
    if haproxy is None:
        print(f"error: {HAPROXY_MISSING}", file=sys.stderr)
        return 1
    host, port = settings.host, settings.port
    first = first_worker_port if first_worker_port is not None else port + 1
    ports = [first + k for k in range(workers)]
    if ports[-1] > 65535:
        raise ParameterError(f"--worker-ports={first}: {workers} ports from there exceed 65535")
    if port in ports:
        raise ParameterError(f"--worker-ports={first} overlaps --port={port}: the workers need "
                             f"{workers} free ports apart from it")
    check_bindable(host, port)
    busy = [p for p in ports if not port_free(p)]
    if busy:
        raise ParameterError(f"worker port(s) {', '.join(map(str, busy))} already in use: choose others "
                             "with --worker-ports FIRST")
    try:
        open_store(settings.database, settings.data_dir).close()   # create (or migrate) it once, before the workers race
    except StoreError as error:
        raise ParameterError(str(error)) from None
    pool = [Worker(k + 1, p, worker_command(p, settings, allow_origins), worker_environment(settings))
            for k, p in enumerate(ports)]
    previous = {s: signal.signal(s, _raise_stop) for s in (signal.SIGINT, signal.SIGTERM)}
    proxy: subprocess.Popen | None = None
    with tempfile.TemporaryDirectory(prefix="amb-lab-hall-") as scratch:
        config = Path(scratch) / "haproxy.cfg"
        config.write_text(haproxy_config(host, port, [("127.0.0.1", p) for p in ports], max_tabs=settings.max_tabs))
        try:
            for worker in pool:
                worker.start()
            deadline = time.monotonic() + READY_TIMEOUT_S
            for worker in pool:
                while not _ready(worker.url):
                    if worker.process.poll() is not None or time.monotonic() > deadline:
                        print(f"error: lab process {worker.index} (port {worker.port}) did not start",
                              file=sys.stderr)
                        return 1
                    time.sleep(0.3)
                worker.start_s = time.monotonic() - worker.started
            proxy = subprocess.Popen([haproxy, "-db", "-f", str(config)], stdin=subprocess.DEVNULL,
                                     start_new_session=True, preexec_fn=_die_with_parent)  # noqa: PLW1509
            time.sleep(0.5)
            if proxy.poll() is not None:
                print(f"error: HAProxy did not start (exit status {proxy.returncode})", file=sys.stderr)
                return 1
            print(f"AMB estimation lab: open {shown_url(host, port)} in a browser "
                  f"({workers} lab processes behind HAProxy; Ctrl+C to stop)", flush=True)
            for line in [*settings.token_lines(), settings.instructor_line()]:
                print(line, flush=True)
            while True:
                time.sleep(POLL_S)
                if proxy.poll() is not None:
                    print(f"error: HAProxy exited (status {proxy.returncode}); stopping", file=sys.stderr)
                    return 1
                supervise(pool)
        except _Stop:
            return 0
        finally:
            for s, handler in previous.items():
                signal.signal(s, signal.SIG_IGN)      # a second Ctrl-C must not cut the clean-up short
            _stop([p for p in [proxy, *(w.process for w in pool)] if p is not None])
            for s, handler in previous.items():
                signal.signal(s, handler)


def supervise(pool: list[Worker]) -> None:
    """Restart exited workers (after a delay that grows while they keep crashing), saying when
    they will answer again (the delay plus what their last start took) and when they do."""
    now = time.monotonic()
    for worker in pool:
        if worker.restart_at is not None:
            if now >= worker.restart_at:
                worker.start()
            continue
        status = worker.process.poll()
        if status is None:
            if worker.exited_at is not None and _ready(worker.url):
                worker.start_s = time.monotonic() - worker.started
                print(f"lab process {worker.index} (port {worker.port}) answers again, "
                      f"{time.monotonic() - worker.exited_at:.0f} s after it exited", file=sys.stderr, flush=True)
                worker.exited_at = None
            continue
        worker.crashes = 0 if now - worker.started > STABLE_AFTER_S else worker.crashes + 1
        delay = RESTART_DELAYS_S[min(worker.crashes, len(RESTART_DELAYS_S)) - 1] if worker.crashes else 0.0
        back = (f"; it answers again in about {delay + worker.start_s:.0f} s (its last start took "
                f"{worker.start_s:.0f} s)") if worker.start_s is not None else ""
        print(f"lab process {worker.index} (port {worker.port}) exited with status {status}; restarting "
              f"{f'in {delay:.0f} s' if delay else 'now'}{back}; HAProxy routes new tabs to the others",
              file=sys.stderr, flush=True)
        worker.exited_at = worker.exited_at or now
        worker.restart_at = now + delay
        if not delay:
            worker.start()
