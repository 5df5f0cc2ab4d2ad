"""The lab's web server: one viser server, one ``LabSession`` per browser tab.

Start-up checks the address first (``access``): a bad ``--host``/``--port`` or
a busy port ends the program with one line and status 2, and the URL printed
is the one actually served.  Every tab's messages pass ``traffic`` (coalesced,
checked); its work runs on its own worker (``session``); its experiment is
autosaved in the ``store``.  Off loopback, each tab must give the class token,
and a browser page from another origin cannot open a tab at all.
"""

from __future__ import annotations

import ctypes
import os
import socket
import sys
import threading
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import viser

from app.infra import access, traffic
from app.infra.database import chosen_database, open_store
from app.infra.store import StoreError
from app.tab.session import LabSession
from lab_modules.exercises import get
from lab_modules.parameters import ParameterError
from lab_modules.scenes.bearing import CAMERA_POSITION

USAGE_ERROR = 2
SWITCH_INTERVAL_S = 0.001
RETURN_MEMORY_EVERY_S = 2.0       # a closed tab's memory goes back to the system within about this


@dataclass
class Settings:
    """What ``python -m app`` serves, checked (``from_args`` raises ``ParameterError``)."""

    host: str = "127.0.0.1"
    port: int = 8080
    exercise: str = "kalman_noise"
    data_dir: Path | None = None
    database: str | None = None            # PostgreSQL URL (None: SQLite in data_dir)
    token: str | None = None               # None: no token asked (loopback only)
    token_source: str = ""                 # "generated", "from --token", ...
    instructor_token: str = field(default_factory=access.new_token)   # the instructor page's (?instructor)
    instructor_source: str = "generated"
    origins: access.OriginPolicy = field(default_factory=access.OriginPolicy)
    max_tabs: int = access.TABS_PER_PROCESS
    trusted_proxies: frozenset[str] = frozenset()

    @classmethod
    def from_args(cls, args) -> Settings:
        host = access.check_host(args.host)
        port = access.check_port(args.port)
        get(args.exercise)
        try:
            database = chosen_database(args.database, os.environ)
        except StoreError as error:
            raise ParameterError(str(error)) from None
        token, source = access.chosen_token(args.token, args.token_file, os.environ)
        if token is None and not access.is_loopback(host):
            token, source = access.new_token(), "generated"
        instructor, instructor_source = access.chosen_token(None, args.instructor_token_file, os.environ,
                                                            access.INSTRUCTOR_TOKEN_VARIABLE, "--instructor-token")
        if instructor is None:
            instructor, instructor_source = access.new_token(), "generated"
        if token is not None and access.token_matches(token, instructor):
            raise ParameterError("the instructor token must differ from the class token: students know that one")
        return cls(host=host, port=port, exercise=args.exercise,
                   data_dir=Path(args.data_dir) if args.data_dir else None, database=database, token=token,
                   token_source=source, instructor_token=instructor, instructor_source=instructor_source,
                   origins=access.OriginPolicy(args.allow_origin or (), host),
                   max_tabs=access.check_max_tabs(args.max_tabs),
                   trusted_proxies=frozenset(access.check_host(a) for a in args.trusted_proxy or ()))

    def instructor_line(self) -> str:
        """What the server prints about the instructor token at start."""
        return (f"Instructor token: {self.instructor_token} ({self.instructor_source}); the instructor page of an "
                "assignment: the lab's address with ?instructor=CODE")

    def token_lines(self) -> list[str]:
        """What the server prints about the class token at start (a weak chosen one is warned of)."""
        if self.token is None:
            return []
        how = "generated; choose one with --token-file or $" + access.TOKEN_VARIABLE \
            if self.token_source == "generated" else self.token_source
        lines = [f"Class token: {self.token} ({how}); every new tab asks for it"]
        bits = access.token_bits(self.token)
        if self.token_source != "generated" and bits < access.STRONG_TOKEN_BITS:
            lines.append(f"warning: this token can be guessed (at most {bits:.0f} bits): wrong tries are "
                         f"throttled, but a generated one is safer (leave the token out)")
        if self.token_source == "from --token":
            lines.append("note: --token shows in the process list to every user of this machine: "
                         f"--token-file FILE or ${access.TOKEN_VARIABLE} do not")
        return lines



def _libc():
    """glibc, where there is one (Linux); None elsewhere."""
    try:
        return ctypes.CDLL("libc.so.6")
    except OSError:
        return None


_LIBC = _libc()
_M_ARENA_MAX = -8


def _limit_malloc_arenas() -> None:
    """Every tab runs threads of its own; glibc would give each a malloc arena that it never
    hands back, so a server whose tabs come and go would grow without leaking an object."""
    if _LIBC is not None:
        _LIBC.mallopt(_M_ARENA_MAX, 2)


def _return_freed_memory() -> None:
    """Give the memory of a closed tab back to the system (glibc keeps freed pages otherwise)."""
    if _LIBC is not None:
        _LIBC.malloc_trim(0)

def _settle_optional_imports() -> None:
    """python-control tries ``from slycot import ...`` on every frequency response and falls back
    to its own code when that fails; a failed import searches the whole import path again each
    time (under the import lock), a third of a tab's analysis.  Without slycot, record once that
    it is missing, so the import fails at once."""
    try:
        import slycot  # noqa: F401
    except ImportError:
        sys.modules["slycot"] = None


def shown_url(host: str, port: int) -> str:
    """The address students open: for a wildcard bind, this machine's address on the network."""
    if host in ("0.0.0.0", "::", ""):
        try:
            with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
                probe.connect(("192.0.2.1", 9))          # no packet is sent: picks the outgoing interface
                host = probe.getsockname()[0]
        except OSError:
            host = socket.gethostname()
    return f"http://{'[' + host + ']' if ':' in host else host}:{port}"


#: viser marks a connection closed before it calls the disconnect callback that stops the tab's
#: threads, so a frame drawn in between is dropped with this warning: expected, not a fault.
warnings.filterwarnings("ignore", message=r"Queued a \w+ on a closed connection", category=UserWarning)


def serve(settings: Settings) -> int:
    """Serve the lab until interrupted; every connecting tab gets its own simulation,
    starting on ``settings.exercise`` (each tab can switch).  Returns the exit status."""
    try:
        access.check_bindable(settings.host, settings.port)
        store = open_store(settings.database, settings.data_dir, log_failures=True)
    except (ParameterError, StoreError) as error:
        print(f"error: {error}", file=sys.stderr)
        return USAGE_ERROR
    _settle_optional_imports()
    # A thread that gives up the GIL (a numpy or LAPACK call, a socket write) waits up to one
    # switch interval to get it back from a busy thread: with the default 5 ms, one tab's
    # analysis, made of many short library calls, slows to a crawl beside another's busy threads.
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    chosen = get(settings.exercise)
    chosen.simulation(chosen.resolve({})).advance(1)       # compile the loop before the first tab
    _limit_malloc_arenas()
    traffic.prepare()                                      # before the server accepts a connection
    traffic.wake_on_the_loop()                             # before viser makes its message buffers
    server = viser.ViserServer(host=settings.host, port=settings.port, label="AMB estimation lab", verbose=False)
    if server.get_port() != settings.port:                 # taken between the check and the start
        server.stop()
        print(f"error: port {settings.port} on {settings.host} is in use (is another lab running?): "
              "choose a free one with --port", file=sys.stderr)
        return USAGE_ERROR
    # The default view direction (the space diagonal), from farther away: the 3D view is the
    # narrow gap between the docked controls and charts, and the scenes must fit its width.
    server.initial_camera.position = tuple(CAMERA_POSITION)
    server.initial_camera.look_at = (0.0, 0.0, 0.0)
    sessions: dict[int, LabSession] = {}
    lock = threading.Lock()
    closed_tabs = threading.Event()          # a tab closed since the freed memory was last returned
    limits = access.Limits(admission=access.Admission(settings.max_tabs))

    def report(client_id: int, text: str) -> None:
        with lock:
            session = sessions.get(client_id)
        if session is not None:
            session.report(text)

    # Both callbacks are async: they run on the event loop, in order, so a tab that closes
    # while its lab is still being built is always found and stopped (its worker builds it).
    @server.on_client_connect
    async def _(client: viser.ClientHandle) -> None:
        headers = policy.headers(client.client_id)
        origin = headers.get("Origin") if headers is not None else None
        host_header = headers.get("Host") if headers is not None else None
        if not settings.origins.permits(origin, host_header):
            print(f"refused a tab from origin {origin!r} (serving {host_header!r})", file=sys.stderr, flush=True)
            policy.close(client.client_id, "origin not allowed")
            return
        forwarded = ",".join(headers.get_all("X-Forwarded-For")) if headers is not None else None
        address = access.client_address(policy.peer(client.client_id), forwarded, settings.trusted_proxies)
        session = LabSession(client, chosen, store, settings.token,
                             on_refused=lambda reason: policy.close(client.client_id, reason), limits=limits,
                             address=address, instructor_token=settings.instructor_token)
        with lock:
            sessions[client.client_id] = session

    @server.on_client_disconnect
    async def _(client: viser.ClientHandle) -> None:
        with lock:
            session = sessions.pop(client.client_id, None)
        policy.forget(client.client_id)
        if session is not None:
            session.close()
        closed_tabs.set()

    # Last: a tab's messages wait for the policy (``traffic.prepare``), so every tab, also one that
    # connected while the server was being set up, meets it and the callbacks above.
    policy = traffic.install(server, report)

    url = shown_url(settings.host, server.get_port())
    print(f"AMB estimation lab: open {url} in a browser (Ctrl+C to stop)", flush=True)
    for line in [*settings.token_lines(), settings.instructor_line()]:
        print(line, flush=True)
    print(f"Saved experiments: {store.where}; at most {settings.max_tabs} tabs (--max-tabs)", flush=True)
    try:
        while True:
            time.sleep(RETURN_MEMORY_EVERY_S)
            if closed_tabs.is_set():          # after the closed tabs' threads ended and freed their memory
                closed_tabs.clear()
                _return_freed_memory()
    except KeyboardInterrupt:
        server.stop()
    return 0
