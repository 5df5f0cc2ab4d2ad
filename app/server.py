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
import socket
import sys
import threading
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import viser

from app.infra import access, traffic
from app.infra.store import Store, StoreError
from app.tab.session import LabSession
from lab_modules.exercises import get
from lab_modules.parameters import ParameterError
from lab_modules.scenes.bearing import CAMERA_POSITION

USAGE_ERROR = 2
SWITCH_INTERVAL_S = 0.001


@dataclass
class Settings:
    """What ``python -m app`` serves, checked (``from_args`` raises ``ParameterError``)."""

    host: str = "127.0.0.1"
    port: int = 8080
    exercise: str = "kalman_noise"
    data_dir: Path | None = None
    token: str | None = None               # None: no token asked (loopback only)
    token_generated: bool = False
    origins: access.OriginPolicy = field(default_factory=access.OriginPolicy)

    @classmethod
    def from_args(cls, args) -> Settings:
        host = access.check_host(args.host)
        port = access.check_port(args.port)
        get(args.exercise)
        token, generated = None, False
        if args.token is not None:
            token = access.check_token(args.token)
        elif not access.is_loopback(host):
            token, generated = access.new_token(), True
        return cls(host=host, port=port, exercise=args.exercise,
                   data_dir=Path(args.data_dir) if args.data_dir else None, token=token,
                   token_generated=generated, origins=access.OriginPolicy(args.allow_origin or ()))



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
        store = Store(settings.data_dir)
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
    traffic.wake_on_the_loop()
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

    def report(client_id: int, text: str) -> None:
        with lock:
            session = sessions.get(client_id)
        if session is not None:
            session.report(text)

    policy = traffic.install(server, report)

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
        session = LabSession(client, chosen, store, settings.token,
                             on_refused=lambda reason: policy.close(client.client_id, reason))
        with lock:
            sessions[client.client_id] = session

    @server.on_client_disconnect
    async def _(client: viser.ClientHandle) -> None:
        with lock:
            session = sessions.pop(client.client_id, None)
        policy.forget(client.client_id)
        if session is not None:
            session.close()
        _return_freed_memory()

    url = shown_url(settings.host, server.get_port())
    print(f"AMB estimation lab: open {url} in a browser (Ctrl+C to stop)", flush=True)
    if settings.token is not None:
        how = "generated; set your own with --token" if settings.token_generated else "from --token"
        print(f"Class token: {settings.token} ({how}); every new tab asks for it", flush=True)
    print(f"Saved experiments: {store.path}", flush=True)
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        server.stop()
    return 0
