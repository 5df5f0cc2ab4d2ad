"""Who may use the lab: address checks at start-up, the class token, the Origin allow-list,
and how many tabs one process gives a lab.

- ``check_host`` / ``check_port`` / ``check_bindable`` validate ``--host`` and
  ``--port`` before anything starts (``ParameterError``: one line, exit 2).
- Served on loopback only, the lab is open to the machine's own browser.  On
  any other address it asks each new tab for the class token (``--token``, or
  one generated and printed at start); ``token_matches`` compares in constant
  time.
- A websocket's ``Origin`` header (sent by every browser) must name the host
  the tab asked for (the ``Host`` header), or one of the allowed origins:
  another web page a student visits cannot open sessions on the lab.
  Clients without an Origin (not a browser) are let through: the token is
  what keeps them out.
- ``Admission``: at most ``--max-tabs`` tabs of one process have a lab; a tab
  beyond waits at a "the lab is full" note and gets in when a place is free.
"""

from __future__ import annotations

import collections
import errno
import hmac
import ipaddress
import secrets
import socket
import sys
import threading
from collections.abc import Callable
from urllib.parse import urlsplit

from lab_modules.parameters import ParameterError

#: Token characters: readable aloud and on a projector (no 0/O, 1/I/L).
TOKEN_ALPHABET = "abcdefghjkmnpqrstuvwxyz23456789"
TOKEN_LENGTH = 8
RESOLVE_TIMEOUT_S = 3.0
LOOPBACK_NAMES = ("localhost",)
#: Tabs one lab process gives a lab by default (``--max-tabs``): one process held 60 tabs at >= 23.9
#: scope updates/s each on the 2-core test machine (README, "A lecture hall"), and the GIL keeps a
#: process to about one core, so this is also the measured capacity per core.
TABS_PER_PROCESS = 60
MAX_TABS_LIMIT = 10_000


def check_port(text) -> int:
    """``--port`` as an int in 1 ... 65535, or ``ParameterError``."""
    try:
        port = int(str(text).strip())
    except ValueError:
        raise ParameterError(f"--port={text!r} is not a whole number: expected 1 ... 65535") from None
    if not 1 <= port <= 65535:
        raise ParameterError(f"--port={text!r} is out of range: expected 1 ... 65535")
    return port


def check_host(host: str) -> str:
    """``--host`` as given if it is an IP address or a name that resolves (within
    ``RESOLVE_TIMEOUT_S``), or ``ParameterError``.  Dotted numbers must be a valid IPv4 address."""
    host = str(host).strip()
    if not host:
        raise ParameterError("--host is empty: expected an address such as 127.0.0.1 or 0.0.0.0")
    try:
        ipaddress.ip_address(host)
        return host
    except ValueError:
        pass
    if all(part.isdigit() for part in host.split(".")) or ":" in host:
        raise ParameterError(f"--host={host!r} is not a valid IP address: expected e.g. 127.0.0.1, "
                             "0.0.0.0 or a host name")
    if _resolve(host) is None:
        raise ParameterError(f"--host={host!r} does not resolve to an address of this machine: expected "
                             "e.g. 127.0.0.1, 0.0.0.0 or a host name")
    return host


def _resolve(host: str) -> list | None:
    """``getaddrinfo`` with a time limit (a missing DNS server can block for long)."""
    result: list = []

    def lookup() -> None:
        try:
            result.extend(socket.getaddrinfo(host, None, type=socket.SOCK_STREAM))
        except OSError:
            pass
    worker = threading.Thread(target=lookup, daemon=True)
    worker.start()
    worker.join(RESOLVE_TIMEOUT_S)
    return result or None


def check_bindable(host: str, port: int) -> None:
    """Refuse a port that is taken or an address that is not this machine's (one line)."""
    infos = _resolve(host) or []
    family = infos[0][0] if infos else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)   # as the server will
        try:
            probe.bind((host, port))
        except OSError as error:
            if error.errno == errno.EADDRINUSE:
                raise ParameterError(f"port {port} on {host} is in use (is another lab running?): "
                                     "choose a free one with --port") from None
            if error.errno == errno.EACCES:
                raise ParameterError(f"port {port} on {host} needs administrator rights: "
                                     "use a port above 1023") from None
            raise ParameterError(f"cannot serve on {host}:{port}: {error.strerror}") from None


def is_loopback(host: str) -> bool:
    """Whether ``host`` reaches only this machine (127.0.0.0/8, ::1, localhost)."""
    if host.strip().lower() in LOOPBACK_NAMES:
        return True
    try:
        return ipaddress.ip_address(host.strip()).is_loopback
    except ValueError:
        infos = _resolve(host) or []
        return bool(infos) and all(ipaddress.ip_address(i[4][0]).is_loopback for i in infos)


def new_token() -> str:
    """A class token: ``TOKEN_LENGTH`` characters easy to read out (about 40 bits)."""
    return "".join(secrets.choice(TOKEN_ALPHABET) for _ in range(TOKEN_LENGTH))


def check_token(text) -> str:
    """``--token`` as given: 4 ... 64 visible characters, or ``ParameterError``."""
    token = str(text).strip()
    if not 4 <= len(token) <= 64 or not token.isprintable() or " " in token:
        raise ParameterError(f"--token must be 4 ... 64 characters without spaces (got {len(token)})")
    return token


def token_matches(expected: str, given) -> bool:
    """Constant-time comparison; surrounding spaces and letter case don't matter."""
    if not isinstance(given, str):
        return False
    return hmac.compare_digest(expected.strip().lower().encode(), given.strip().lower().encode())


def _origin_key(origin: str) -> str | None:
    """``scheme://host:port`` of an origin or URL, lower case, default ports filled in."""
    parts = urlsplit(origin.strip())
    if not parts.scheme or not parts.hostname:
        return None
    port = parts.port or {"http": 80, "https": 443, "ws": 80, "wss": 443}.get(parts.scheme, 0)
    scheme = {"ws": "http", "wss": "https"}.get(parts.scheme, parts.scheme)
    host = parts.hostname.lower()
    return f"{scheme}://{'[' + host + ']' if ':' in host else host}:{port}"


class OriginPolicy:
    """Which browser pages may open a websocket to the lab: the page the lab
    itself served (Origin host equals the request's Host header) and the
    origins in ``allowed`` (e.g. ``https://lab.example.org`` behind a proxy)."""

    def __init__(self, allowed: tuple[str, ...] | list[str] = ()):
        self.allowed = set()
        for origin in allowed:
            key = _origin_key(origin)
            if key is None:
                raise ParameterError(f"--allow-origin={origin!r} is not an origin: expected e.g. "
                                     "http://lab.example.org:8080")
            self.allowed.add(key)

    def permits(self, origin: str | None, host_header: str | None) -> bool:
        """Whether a websocket with these ``Origin`` and ``Host`` headers may connect."""
        if origin is None:
            return True                                   # not a browser: the token decides
        key = _origin_key(origin)
        if key is None:
            return False                                  # "null" (sandboxed or file:// pages)
        if key in self.allowed:
            return True
        if not host_header:
            return False
        scheme = key.split("://", 1)[0]
        return _origin_key(f"{scheme}://{host_header}") == key


def check_max_tabs(text) -> int:
    """``--max-tabs`` as an int in 1 ... ``MAX_TABS_LIMIT``, or ``ParameterError``."""
    try:
        tabs = int(str(text).strip())
    except ValueError:
        raise ParameterError(f"--max-tabs={text!r} is not a whole number: expected 1 ... {MAX_TABS_LIMIT}") from None
    if not 1 <= tabs <= MAX_TABS_LIMIT:
        raise ParameterError(f"--max-tabs={text!r} is out of range: expected 1 ... {MAX_TABS_LIMIT}")
    return tabs


class Admission:
    """The tabs of one process that have a lab: at most ``limit``.  A tab beyond waits for a
    place in line, first come first served (``wait_to_enter``); the first refusal while full is
    logged once, again only after the lab was below 90 % of its places."""

    def __init__(self, limit: int = TABS_PER_PROCESS):
        self.limit = limit
        self.holders: set = set()
        self.line: collections.deque = collections.deque()
        self.changed = threading.Condition()
        self.full_logged = False

    def try_enter(self, holder) -> bool:
        """Take a place if one is free and nobody waits for it; else log (once) that the lab is full."""
        with self.changed:
            if len(self.holders) < self.limit and not self.line:
                self.holders.add(holder)
                return True
            if not self.full_logged:
                print(f"the lab is full ({self.limit} tabs, --max-tabs): new tabs wait for a place",
                      file=sys.stderr, flush=True)
                self.full_logged = True
            return False

    def wait_to_enter(self, holder, given_up: Callable[[], bool]) -> bool:
        """Wait in line until there is a place (True: ``holder`` has it) or ``given_up()`` (False)."""
        with self.changed:
            self.line.append(holder)
            try:
                self.changed.wait_for(lambda: given_up() or (self.line[0] is holder
                                                             and len(self.holders) < self.limit))
            finally:
                self.line.remove(holder)
                self.changed.notify_all()             # the next in line may be first now
            if given_up():
                return False
            self.holders.add(holder)
            return True

    def leave(self, holder) -> None:
        """``holder`` gives its place back (if it had one); waiting tabs look again (also the one
        that closed while waiting)."""
        with self.changed:
            self.holders.discard(holder)
            if len(self.holders) < 0.9 * self.limit:
                self.full_logged = False
            self.changed.notify_all()
