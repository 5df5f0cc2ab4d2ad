"""Who may use the lab: address checks at start-up, the class token, the Origin allow-list,
and how many tabs one process gives a lab.

- ``check_host`` / ``check_port`` / ``check_bindable`` validate ``--host`` and
  ``--port`` before anything starts (``ParameterError``: one line, exit 2).
- Served on loopback only, the lab is open to the machine's own browser.  On
  any other address it asks each new tab for the class token (``--token``,
  ``--token-file``, the environment variable ``TOKEN_VARIABLE``, or one generated
  and printed at start: ``TOKEN_GROUPS`` groups of four characters, about 59
  bits); ``token_matches`` compares in constant time.  A lecture hall hands the
  token to its processes in their environment, never on a command line (which
  every user of the machine can read in the process list).
- ``Throttle``: failed tries (wrong class tokens, experiment codes that open
  nothing) per client address, across all its tabs and connections, logged once
  per address.  The address is the websocket's peer, or the ``X-Forwarded-For``
  HAProxy adds when the peer is a trusted proxy (loopback, ``--trusted-proxy``).
- A websocket's ``Origin`` header (sent by every browser) must name the host
  the tab asked for (the ``Host`` header), or one of the allowed origins:
  another web page a student visits cannot open sessions on the lab.  That
  ``Host`` must be a name the lab serves (an address of this machine, a
  loopback name, the machine's name, ``--host``, an ``--allow-origin`` host):
  a page whose own name an attacker re-pointed at the lab (DNS rebinding) sends
  ``Host`` and ``Origin`` of that name, and is refused.
  Clients without an Origin (not a browser) are let through: the token is
  what keeps them out.
- ``Admission``: at most ``--max-tabs`` tabs of one process have a lab; a tab
  beyond waits at a "the lab is full" note and gets in when a place is free.
"""

from __future__ import annotations

import collections
import errno
import functools
import hmac
import ipaddress
import math
import secrets
import socket
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from urllib.parse import urlsplit

from lab_modules.parameters import ParameterError

#: Token characters: readable aloud and on a projector (no 0/O, 1/I/L).
TOKEN_ALPHABET = "abcdefghjkmnpqrstuvwxyz23456789"
TOKEN_GROUPS = 3                  # of four characters: 12 × log2(31) = 59 bits
TOKEN_VARIABLE = "AMB_LAB_TOKEN"
INSTRUCTOR_TOKEN_VARIABLE = "AMB_LAB_INSTRUCTOR_TOKEN"   # the instructor page's token (never the class's)
#: A chosen token weaker than this is worth a warning at start [bits].
STRONG_TOKEN_BITS = 50
RESOLVE_TIMEOUT_S = 3.0
LOOPBACK_NAMES = ("localhost",)
#: Tabs one lab process gives a lab by default (``--max-tabs``): one process held 60 tabs at >= 23.9
#: scope updates/s each on the 2-core test machine (README, "A lecture hall"), and the GIL keeps a
#: process to about one core, so this is also the measured capacity per core.
TABS_PER_PROCESS = 60
MAX_TABS_LIMIT = 10_000
#: Wrong class tokens an address may try at once, and per minute after that (a student who
#: mistypes a few times is not held up; a word list of 10,000 takes 17 hours per lab process).
TOKEN_TRIES_BURST, TOKEN_TRIES_PER_MINUTE = 10, 10
#: Experiment codes that open nothing, per address (a typo or two is free) and per tab.
CODE_TRIES_BURST, CODE_TRIES_PER_MINUTE = 10, 10
TAB_CODE_TRIES_BURST, TAB_CODE_TRIES_PER_MINUTE = 5, 6
MAX_ADDRESSES = 10_000            # a throttle forgets addresses back at their full allowance beyond this


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


def is_address(host: str) -> bool:
    """Whether ``host`` is an IP address (not a name)."""
    try:
        ipaddress.ip_address(host.strip())
    except ValueError:
        return False
    return True


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
    """A class token easy to read out: ``TOKEN_GROUPS`` groups of four characters (``k7mq-x3pt-9hwa``)."""
    return "-".join("".join(secrets.choice(TOKEN_ALPHABET) for _ in range(4)) for _ in range(TOKEN_GROUPS))


def check_token(text, source: str = "--token") -> str:
    """A chosen token as given: 4 ... 64 visible characters, or ``ParameterError``."""
    token = str(text).strip()
    if not 4 <= len(token) <= 64 or not token.isprintable() or " " in token:
        raise ParameterError(f"{source} must be 4 ... 64 characters without spaces (got {len(token)})")
    return token


def chosen_token(given: str | None, file: str | None, environment: dict, variable: str = TOKEN_VARIABLE,
                 option: str = "--token") -> tuple[str | None, str]:
    """The class token from ``--token``, ``--token-file`` (its first line) or ``TOKEN_VARIABLE``, in
    that order, and where it came from; (None, "") if none is given.  The instructor token the same
    way from ``--instructor-token``, ``--instructor-token-file`` or ``INSTRUCTOR_TOKEN_VARIABLE``."""
    if given is not None:
        return check_token(given, option), f"from {option}"
    if file is not None:
        try:
            with open(file, encoding="utf-8") as handle:
                first = handle.readline(1000)
        except (OSError, UnicodeDecodeError) as error:
            reason = error.strerror if isinstance(error, OSError) else "not a text file"
            raise ParameterError(f"{option}-file {file!r}: {reason}") from None
        return check_token(first, f"{option}-file"), f"from {option}-file"
    if environment.get(variable):
        return check_token(environment[variable], variable), f"from {variable}"
    return None, ""


def token_bits(token: str) -> float:
    """What guessing ``token`` takes at best [bits], from its length and the kinds of characters
    it uses (a word or a name takes far fewer: this is an upper bound)."""
    kinds = (str.islower, str.isupper, str.isdigit)
    alphabet = sum(size for kind, size in zip(kinds, (26, 26, 10), strict=True) if any(kind(c) for c in token))
    alphabet += 32 if any(not c.isalnum() for c in token) else 0
    return len(normal_token(token)) * math.log2(max(alphabet, 2))


def normal_token(text: str) -> str:
    """A token as compared: letter case, spaces and dashes do not matter."""
    return "".join(text.split()).replace("-", "").lower()


def token_matches(expected: str, given) -> bool:
    """Constant-time comparison of the ``normal_token`` forms."""
    if not isinstance(given, str):
        return False
    return hmac.compare_digest(normal_token(expected).encode(), normal_token(given).encode())


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
    itself served (Origin host equals the request's Host header, and that is a
    name the lab serves) and the origins in ``allowed`` (e.g.
    ``https://lab.example.org`` behind a proxy)."""

    def __init__(self, allowed: tuple[str, ...] | list[str] = (), served_host: str = "127.0.0.1"):
        self.allowed = set()
        for origin in allowed:
            key = _origin_key(origin)
            if key is None:
                raise ParameterError(f"--allow-origin={origin!r} is not an origin: expected e.g. "
                                     "http://lab.example.org:8080")
            self.allowed.add(key)
        self.names = {*LOOPBACK_NAMES, served_host.strip().lower(), socket.gethostname().lower(),
                      socket.getfqdn().lower(), *(urlsplit(key).hostname for key in self.allowed)}

    def serves(self, host_header: str) -> bool:
        """Whether a request's ``Host`` names this lab: an address of this machine or one of ``names``."""
        try:
            host = urlsplit(f"//{host_header.strip()}").hostname
        except ValueError:
            return False
        return bool(host) and (host in self.names or _is_local_address(host))

    def permits(self, origin: str | None, host_header: str | None) -> bool:
        """Whether a websocket with these ``Origin`` and ``Host`` headers may connect."""
        if origin is None:
            return True                                   # not a browser: the token decides
        key = _origin_key(origin)
        if key is None:
            return False                                  # "null" (sandboxed or file:// pages)
        if key in self.allowed:
            return True
        if not host_header or not self.serves(host_header):
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


class Throttle:
    """Failed tries per client address, across all its tabs and connections (a token bucket):
    ``burst`` at once, then one every ``60 / per_minute`` s.  The first time an address runs out
    is logged (``what``: what was tried), once per address."""

    def __init__(self, what: str, burst: int, per_minute: float, log: bool = True):
        self.what, self.burst, self.refill_per_s, self.log = what, burst, per_minute / 60.0, log
        self.buckets: dict[str, tuple[float, float]] = {}   # address -> (tries left, when counted)
        self.logged: set[str] = set()
        self.lock = threading.Lock()

    def _left(self, address: str, now: float) -> float:
        left, then = self.buckets.get(address, (self.burst, now))
        return min(self.burst, left + (now - then) * self.refill_per_s)

    def wait_s(self, address: str) -> float:
        """How long ``address`` must wait before its next try [s] (0: it may try now)."""
        with self.lock:
            left = self._left(address, time.monotonic())
        return 0.0 if left >= 1 else (1 - left) / self.refill_per_s

    def failed(self, address: str) -> None:
        """One failed try from ``address``."""
        with self.lock:
            now = time.monotonic()
            left = self._left(address, now) - 1
            self.buckets[address] = (left, now)
            if len(self.buckets) > MAX_ADDRESSES:         # forget addresses that have their full allowance back
                self.buckets = {a: b for a, b in self.buckets.items() if self._left(a, now) < self.burst}
            first = left < 1 and address not in self.logged and self.log
            if first:
                self.logged.add(address)
        if first:
            print(f"{self.what}: too many failed tries from {address}; its tries are limited to "
                  f"{self.refill_per_s * 60:g} per minute (logged once per address)", file=sys.stderr, flush=True)


def client_address(peer: str | None, forwarded_for: str | None, trusted_proxies: frozenset[str]) -> str:
    """The address a tab comes from: the websocket's ``peer``, or, when the peer is a trusted proxy
    (loopback, or one of ``trusted_proxies``), the last address in its ``X-Forwarded-For`` (the one
    the proxy added: what comes before it, the client may have written itself)."""
    peer = peer or "unknown"
    trusted = peer in trusted_proxies or (peer != "unknown" and _is_loopback_ip(peer))
    if forwarded_for and trusted:
        return forwarded_for.split(",")[-1].strip() or peer
    return peer


@functools.lru_cache(maxsize=256)
def _is_local_address(host: str) -> bool:
    """Whether ``host`` is an IP address of this machine (one a socket can be bound to)."""
    try:
        family = socket.AF_INET6 if ipaddress.ip_address(host).version == 6 else socket.AF_INET
    except ValueError:
        return False                                       # a name
    with socket.socket(family, socket.SOCK_DGRAM) as probe:
        try:
            probe.bind((host, 0))
        except OSError:
            return False
    return True


def _is_loopback_ip(address: str) -> bool:
    try:
        return ipaddress.ip_address(address).is_loopback
    except ValueError:
        return False


@dataclass
class Limits:
    """What the tabs of one process share to keep each other within bounds."""

    admission: Admission = field(default_factory=Admission)
    token_tries: Throttle = field(default_factory=lambda: Throttle("class token", TOKEN_TRIES_BURST,
                                                                   TOKEN_TRIES_PER_MINUTE))
    code_tries: Throttle = field(default_factory=lambda: Throttle("experiment codes", CODE_TRIES_BURST,
                                                                  CODE_TRIES_PER_MINUTE))
