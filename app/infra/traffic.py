"""What one tab may send: its messages are read, checked and coalesced before
viser acts on them, so one tab cannot starve the others.

viser reads each connection's messages in ``viser.infra._infra._message_consumer``
and hands every one to its handlers (GUI updates become thread-pool jobs).
``install`` replaces that reader with ``_consumer`` below, which per connection

- **coalesces GUI updates** (and camera moves): an update is passed on at once if the control had
  none in the last ``COALESCE_S``; otherwise only the newest value is kept and
  passed on when that interval is over.  A burst of 10,000 slider updates
  costs their decoding and one dispatch per control per interval;
- **checks uploads** against ``uploads.Uploads`` (a size limit per file, one unfinished upload
  per tab, a budget per process, stale uploads dropped and their parts freed);
- **answers invalid messages** (undecodable, or rejected by a handler) in the
  tab through ``Traffic.report`` and logs one line per client, not per message;
  a GUI update may only change a control's ``value`` (what a browser sends: a
  tab could otherwise set a control's internal attributes, such as its
  callbacks), and a dropdown's value must be one of its options.

The origin check needs the websocket's request headers: ``headers`` finds
them by client id.

``wake_on_the_loop`` (before the server starts) mends viser's other direction: a tab's
outgoing messages are pushed by the frame and analysis threads, and the wake-up of the
connection's writer could be lost for good (``LoopSideEvent``).
"""

from __future__ import annotations

import asyncio
import inspect
import sys
import threading
import time
from collections.abc import Callable

import msgspec
import viser
import viser.infra._infra as infra
from viser import _messages
from viser.infra._async_message_buffer import AsyncMessageBuffer

from app.infra import viser_internals
from app.infra.uploads import MAX_UPLOAD_BYTES, Uploads, describe_bytes

#: A control's updates are acted on at most once per this interval [s] (newest value wins).
COALESCE_S = 0.02
#: Share of the event loop one connection's messages may take, and the burst it may take at once [s].
LOOP_SHARE = 0.05
LOOP_BURST_S = 0.02
#: What reading one message costs beyond the time measured here (the websocket library parses
#: each frame before ``recv`` returns it) [s]: charged to the connection's share as well.
MESSAGE_COST_S = 20e-6
#: A connection yields the event loop to the others after this many messages in a row.
YIELD_EVERY = 32
#: Invalid messages from one client beyond this many are not reported again in its tab.
REPORTS_PER_CLIENT = 5


class Traffic:
    """The per-client policy installed into one viser server."""

    def __init__(self, server: viser.ViserServer, report: Callable[[int, str], None]):
        self.server = server
        self.report_to_tab = report        # (client id, one line): shown in that tab
        self.logged: set[int] = set()
        self.reported: dict[int, int] = {}
        self.lock = threading.Lock()
        self.uploads = Uploads()           # touched on the event loop only
        self.sweep_scheduled = False
        self.stats = {"received": 0, "dispatched_updates": 0, "coalesced": 0, "invalid": 0, "refused_uploads": 0,
                      "dropped_uploads": 0}

    # -- lookups ------------------------------------------------------------------
    def _connections(self) -> dict:
        return self.server._websock_server._live_connections

    def client_id_of(self, websocket) -> int | None:
        for client_id, connection in tuple(self._connections().items()):
            if connection is websocket:
                return client_id
        return None

    def headers(self, client_id: int):
        """The websocket request's headers of a connected client (None once it is gone)."""
        connection = self._connections().get(client_id)
        request = getattr(connection, "request", None)
        return None if request is None else request.headers

    def peer(self, client_id: int) -> str | None:
        """The address a connected client's websocket comes from (None once it is gone)."""
        address = getattr(self._connections().get(client_id), "remote_address", None)
        return str(address[0]) if address else None

    def close(self, client_id: int, reason: str) -> None:
        """Close a client's websocket (policy violation) from any thread or the event loop."""
        connection = self._connections().get(client_id)
        if connection is None:
            return
        loop = self.server._websock_server._background_event_loop
        coroutine = connection.close(1008, reason[:120])
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is loop:
            loop.create_task(coroutine)
        else:
            asyncio.run_coroutine_threadsafe(coroutine, loop)

    # -- GUI updates --------------------------------------------------------------------
    def refused_update(self, client_id: int | None, message) -> str | None:
        """Why a tab's GUI update is refused (None: pass it on): only a control's value, and for a
        dropdown one of its options; never of a disabled control (e.g. a parameter an assignment fixes)."""
        if not isinstance(message.updates, dict):
            return "malformed GUI update"
        if set(message.updates) != {"value"}:
            return "a change of a control the browser never sends"
        handle = viser_internals.gui_input_handle(self.server, client_id, message.uuid)
        if isinstance(handle, viser.GuiDropdownHandle) and message.updates["value"] not in handle.options:
            return "a choice the control does not offer"
        if getattr(handle, "disabled", False):
            return "a change of a control that is fixed"
        return None

    # -- uploads ----------------------------------------------------------------------
    def free_uploads(self, keys) -> None:
        """Forget unfinished uploads and free the parts viser holds of them (on the event loop)."""
        self.uploads.drop(keys)
        for client_id, transfer in keys:
            self.stats["dropped_uploads"] += 1
            viser_internals.forget_upload(self.server, client_id, transfer)

    def sweep_uploads(self) -> None:
        """Drop stale uploads, and look again while any upload is unfinished (on the event loop)."""
        loop = asyncio.get_running_loop()
        self.free_uploads(self.uploads.stale(loop.time()))
        self.sweep_scheduled = bool(self.uploads.transfers)
        if self.sweep_scheduled:
            loop.call_later(self.uploads.stale_s / 2, self.sweep_uploads)

    # -- invalid input ----------------------------------------------------------------
    def invalid(self, client_id: int | None, what: str) -> None:
        """One bad message: a line in the server log (once per client) and in the tab (a few times)."""
        with self.lock:
            self.stats["invalid"] += 1
            first = client_id not in self.logged
            self.logged.add(client_id)
            shown = self.reported.get(client_id, 0)
            self.reported[client_id] = shown + 1
        if first:
            print(f"client {client_id}: invalid message ({what}); further ones from this client are not logged",
                  file=sys.stderr, flush=True)
        if client_id is not None and shown < REPORTS_PER_CLIENT:
            self.report_to_tab(client_id, f"The lab ignored a message it could not use ({what}).")

    def forget(self, client_id: int) -> None:
        """A tab is gone (on the event loop): so are its unfinished uploads."""
        with self.lock:
            self.logged.discard(client_id)
            self.reported.pop(client_id, None)
        self.free_uploads(self.uploads.of_client(client_id))


_installed: Traffic | None = None
_original_dispatch = infra.WebsockMessageHandler._handle_incoming_message
#: How often a connection made before ``install`` looks whether the policy is there [s].
INSTALL_POLL_S = 0.01


def prepare() -> None:
    """Put the reader in front of viser's handlers before the server is made: viser serves as soon
    as it is made, and a tab that connects in that moment (a class reconnecting to a restarted
    process) waits for ``install`` instead of passing the policy by."""
    infra._message_consumer = _consumer
    infra.WebsockMessageHandler._handle_incoming_message = _guarded_dispatch


def install(server: viser.ViserServer, report: Callable[[int, str], None]) -> Traffic:
    """The per-tab policy for ``server`` (one server per process; ``prepare`` first)."""
    global _installed
    prepare()
    _installed = Traffic(server, report)
    return _installed


async def _guarded_dispatch(self, client_id, message) -> None:
    """viser's dispatch, with a handler's exception reported instead of a traceback per message."""
    try:
        await _original_dispatch(self, client_id, message)
    except Exception as error:   # a handler rejected the message's content
        if _installed is None:
            raise
        _installed.invalid(client_id, f"{type(message).__name__}: {type(error).__name__} {str(error)[:80]}")


class _Header(msgspec.Struct):
    """The two fields that decide what happens to a message (the rest is decoded only if needed)."""

    type: str
    uuid: object = None


_HEADER = msgspec.msgpack.Decoder(_Header)
_COALESCED = {"GuiUpdateMessage", "ViewerCameraMessage"}


async def _consumer(websocket, handle_message: Callable, message_class) -> None:
    """viser's message reader with coalescing, upload limits, reports and a share of the
    event loop per connection (see the module docstring)."""
    while _installed is None:                     # connected while the server was being set up
        await asyncio.sleep(INSTALL_POLL_S)
    traffic = _installed
    loop = asyncio.get_running_loop()
    client_id: int | None = None
    pending: dict[str, bytes] = {}                # control uuid (or "camera") -> newest raw update
    last_sent: dict[str, float] = {}              # control uuid -> loop time of its last dispatch
    scheduled: set[str] = set()
    allowance, refilled, count = LOOP_BURST_S, time.perf_counter(), 0

    def decode(raw: bytes):
        try:
            return message_class.deserialize(raw)
        except Exception as error:  # noqa: BLE001 - anything a hostile or broken client can send
            traffic.invalid(client_id, f"undecodable: {type(error).__name__}")
            return None

    def dispatch(key: str) -> None:
        scheduled.discard(key)
        raw = pending.pop(key, None)
        if raw is None:
            return
        last_sent[key] = loop.time()
        message = decode(raw)
        if isinstance(message, _messages.GuiUpdateMessage) and (problem := traffic.refused_update(client_id, message)):
            traffic.invalid(client_id, problem)
        elif message is not None:
            traffic.stats["dispatched_updates"] += 1
            handle_message(message)

    def take(raw) -> None:
        """Act on one message: coalesce, check, or pass on."""
        if not isinstance(raw, bytes):
            traffic.invalid(client_id, "a text frame")
            return
        try:
            header = _HEADER.decode(raw)
        except (msgspec.DecodeError, msgspec.ValidationError) as error:
            traffic.invalid(client_id, f"undecodable: {str(error)[:60]}")
            return
        if header.type in _COALESCED:
            if header.type == "ViewerCameraMessage":
                key = "camera"                             # the newest view is all that matters
            elif isinstance(header.uuid, str):
                key = header.uuid
            else:
                traffic.invalid(client_id, "malformed GUI update")
                return
            if key in pending:
                traffic.stats["coalesced"] += 1
            pending[key] = raw                             # the newest value wins
            wait = last_sent.get(key, -1e9) + COALESCE_S - loop.time()
            if wait <= 0:
                dispatch(key)
            elif key not in scheduled:
                scheduled.add(key)
                loop.call_later(wait, dispatch, key)
            return
        message = decode(raw)
        if message is None:
            return
        if isinstance(message, _messages.FileTransferStartUpload):
            declared = message.size_bytes
            if not isinstance(declared, int) or not isinstance(message.part_count, int) or declared < 0 \
                    or message.part_count < 0 or not isinstance(message.transfer_uuid, str):
                traffic.invalid(client_id, "malformed upload")
                return
            if declared > MAX_UPLOAD_BYTES:
                traffic.stats["refused_uploads"] += 1
                if client_id is not None:
                    traffic.report_to_tab(client_id, f"The file is {describe_bytes(declared)}; the largest "
                                                     f"accepted is {describe_bytes(MAX_UPLOAD_BYTES)}.")
                return
            accepted, dropped = traffic.uploads.start(client_id, message.transfer_uuid, declared, loop.time())
            traffic.free_uploads(dropped)
            if not accepted:
                traffic.stats["refused_uploads"] += 1
                if client_id is not None:
                    traffic.report_to_tab(client_id, "The lab is receiving other files just now: "
                                                     "load yours again in a minute.")
                return
            if not traffic.sweep_scheduled:
                traffic.sweep_scheduled = True
                loop.call_later(traffic.uploads.stale_s / 2, traffic.sweep_uploads)
        elif isinstance(message, _messages.FileTransferPart):
            content = message.content
            if not isinstance(content, bytes) or not isinstance(message.transfer_uuid, str):
                traffic.invalid(client_id, "malformed upload part")
                return
            progress = traffic.uploads.part(client_id, message.transfer_uuid, len(content), loop.time())
            if progress is None:
                return
            if progress == "overflow":
                traffic.free_uploads([(client_id, message.transfer_uuid)])
                traffic.invalid(client_id, "upload parts beyond the declared size")
                return
        handle_message(message)

    while True:
        raw = await websocket.recv()
        began = time.perf_counter()
        traffic.stats["received"] += 1
        if client_id is None:
            client_id = traffic.client_id_of(websocket)
        take(raw)
        # This connection's share of the event loop: beyond it, stop reading for a while
        # (the client's sends back up in TCP), and let the other connections run regularly.
        now = time.perf_counter()
        allowance = min(LOOP_BURST_S, allowance + (began - refilled) * LOOP_SHARE) - (now - began) - MESSAGE_COST_S
        refilled = now
        count += 1
        if allowance < 0:
            await asyncio.sleep(-allowance / LOOP_SHARE)
        elif count % YIELD_EVERY == 0:
            await asyncio.sleep(0)


class LoopSideEvent(asyncio.Event):
    """The wake-up of a connection's writer (viser's ``AsyncMessageBuffer.message_event``),
    changed only on its event loop.

    viser's ``push`` runs on the thread that sends (a frame thread) and sets the event twice:
    directly, then on the loop through ``call_soon_threadsafe`` (or at the end of the atomic
    block, ``atomic_end``).  The direct set races with ``Event.wait`` on the loop, which checks
    the flag and then registers its waiter: a set from another thread in between (a GIL switch
    there) raises the flag and wakes no one, the loop-side set then finds the flag raised and
    does nothing, and the writer sleeps for good with its tab's messages piling up: the tab gets
    nothing more while its websocket stays open.  Only the loop-side set is kept; viser makes it
    for every push (``tests/test_traffic.py`` holds it to that)."""

    def __init__(self, loop: asyncio.AbstractEventLoop):
        super().__init__()
        self.owner = loop

    def set(self) -> None:
        if asyncio.events._get_running_loop() is self.owner:
            super().set()


def wake_on_the_loop() -> None:
    """Every message buffer viser makes from now on wakes its writer on the event loop only
    (``LoopSideEvent``); call before the server is made (its broadcast buffer is made then)."""
    if getattr(AsyncMessageBuffer.__init__, "wakes_on_the_loop", False):
        return
    made = AsyncMessageBuffer.__init__

    def __init__(self, *args, **kwargs) -> None:
        made(self, *args, **kwargs)
        self.message_event = LoopSideEvent(self.event_loop)

    __init__.wakes_on_the_loop = True
    AsyncMessageBuffer.__init__ = __init__


def callback(function: Callable) -> Callable:
    """An async GUI callback that runs ``function(event)`` inline on the event loop
    (viser awaits coroutine callbacks instead of queueing them on its shared thread pool):
    ``function`` must only record the event and return at once."""
    async def on_event(event) -> None:
        function(event)
    assert not inspect.iscoroutinefunction(function)
    return on_event
