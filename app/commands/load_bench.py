"""``python -m app bench --clients N [--workers W]``: a lecture hall of headless tabs.

Starts the lab on loopback (through HAProxy with ``W`` workers when W > 1),
then connects headless websocket clients that behave like browser tabs: each
receives and decodes everything the lab sends (zstd + msgpack, with the binary
arrays), sends a camera message on connect and every few seconds, and moves
the position-noise slider every few seconds.  Clients are added in steps up
to N; at each step every tab's scope updates per second, bytes per second and
the server's CPU time (all its processes, HAProxy included, from ``/proc``)
are measured over a fixed window, and every tab that stalled in it is named with
the reason (``Tab.stall``: no scope update for more than ``STALL_S``, and whether
any other message came meanwhile, or the connection ended: closed by the server
with its close code, lost, or a frame the tab could not read).  The largest step
at which every tab still gets ``MIN_UPDATES_PER_S`` scope updates per second and
none stalled is the capacity.  The run stops at the first step that fails, so it
is bounded in time.

``--breakdown`` also attributes the received bytes to message kinds (scope
chart data, readouts, 3D view, ...).  ``--mix`` spreads the tabs over every
exercise (each switches to its own after the lab opens) and over the panel tabs
(``PANEL_MIX``: half on the Scope, the others on the Pole map or the Analysis tab,
reported as the browser's beacon does); each moves a control its exercise's
Scope readouts depend on (``app.commands.tab_mix``).  The figures of a
step and their printing: ``app.commands.load_report``.
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import os
import random
import statistics
import sys
import tempfile
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import msgspec
import viser
import websockets.asyncio.client
import zstandard

from app.commands.lab_processes import cpu_seconds, lab_server, process_tree
from app.commands.load_report import MIN_UPDATES_PER_S, Step, print_step, print_summary
from app.commands.tab_mix import KALMAN_NOISE_MOVE, PANEL_MIX, SliderMove, mix_move
from app.infra.viser_internals import HIDDEN_LABEL, SHOWN_LABEL
from lab_modules.exercises import SCOPE, get, registry
from lab_modules.parameters import ParameterError

PROTOCOL = f"viser-v{viser.__version__}"      # the subprotocol a viser client of this version offers
TARGET_BYTES_PER_S = 150e3
CAMERA_PERIOD_S = 3.0                         # each tab sends a camera message this often ...
SLIDER_EVERY = 3                              # ... and moves a slider with every third one (an analysis: ~0.1 s CPU)
CONNECT_RATE_PER_S = 10.0                     # new tabs per second while ramping up
SETTLE_S = 4.0                                # after the last new tab of a step, before measuring ...
SETTLE_MAX_S = 90.0                           # ... and until every tab streams (a busy machine builds slowly)
WORKER_HEADER = "X-Lab-Worker"                # set by the generated HAProxy configuration
STALL_S = 2.0                                 # a tab with no scope update for longer than this has stalled
#: A tab on another panel gets no scope updates (the Scope is hidden); it gets its readouts, status line
#: and 3D view every second or so: with no message at all for longer than this, it has stalled.
STALL_AWAY_S = 5.0


def scope_titles(exercise_name: str) -> tuple[str, ...]:
    """The titles of the exercise's scope charts as the session shows them."""
    return tuple(f"{c.title} [{c.unit}]" for c in get(exercise_name).charts)


def decode_frame(frame: bytes) -> tuple[list[dict], list[int], int]:
    """One websocket frame of viser's wire format: (messages, binary buffer lengths,
    compressed msgpack length).  The frame is [u64 msgpack length][u64 compressed
    length][zstd msgpack][8-byte aligned binary buffers]."""
    raw_len = int.from_bytes(frame[0:8], "little")
    compressed_len = int.from_bytes(frame[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(frame[16:16 + compressed_len], max_output_size=raw_len)
    payload = msgspec.msgpack.decode(inner)
    return payload["messages"], list(payload["binaryBufferLengths"]), compressed_len


def _closing(error: websockets.ConnectionClosed) -> str:
    """Who closed the connection, with which code and reason."""
    if error.rcvd is not None:
        return f"closed by server with code {error.rcvd.code}" + (f" ({error.rcvd.reason})" if error.rcvd.reason else "")
    return "connection lost without a close frame"


def _binary_bytes(value, lengths: list[int]) -> int:
    """Bytes of the binary buffers a decoded message refers to."""
    if isinstance(value, dict):
        if "__binary_index" in value and "dtype" in value:
            return lengths[value["__binary_index"]]
        return sum(_binary_bytes(v, lengths) for v in value.values())
    if isinstance(value, (list, tuple)):
        return sum(_binary_bytes(v, lengths) for v in value)
    return 0


@dataclass
class Tab:
    """One headless tab: a websocket client that receives and decodes what the lab sends."""

    url: str
    titles: tuple[str, ...]                   # scope chart titles
    breakdown: bool = False
    slider_every: int = SLIDER_EVERY           # 0: the tab never moves a slider
    move: SliderMove = KALMAN_NOISE_MOVE       # the slider it moves and the readout that answers
    switch_to: str | None = None              # the title of the exercise to choose once the lab opens
    panel: str = SCOPE                        # the panel tab it shows
    received_bytes: int = 0
    scope_times: list[float] = field(default_factory=list)   # arrival of each update of the first scope chart
    kind_bytes: Counter = field(default_factory=Counter)
    kind_count: Counter = field(default_factory=Counter)
    kinds: dict[str, str] = field(default_factory=dict)      # GUI uuid -> kind of element
    slider: str | None = None
    worker: str | None = None
    connected: bool = False
    closed: str | None = None                 # why the connection ended
    ended_at: float | None = None             # when it ended before the bench stopped it
    frame_times: list[float] = field(default_factory=list)   # arrival of every frame (any message)
    scope_uuid: str | None = None
    answers: list = field(default_factory=list)               # replies due to the lab's requests
    moved_at: float | None = None             # the newest slider move whose readout has not come yet
    readout: str | None = None                # the newest value of ``move.readout_row``
    latencies: list[tuple[float, float]] = field(default_factory=list)   # (arrival, seconds since the move)

    def _kind(self, message: dict) -> str:
        kind = message["type"]
        if kind == "GuiUpdateMessage":
            return self.kinds.get(message["uuid"], "GUI update") + " update"
        if kind.startswith("Gui") and "props" in message:
            props = message["props"]
            label = props.get("label") or props.get("title") or ""
            if kind == "GuiUplotMessage":
                self.kinds[message["uuid"]] = "scope chart" if label in self.titles else "static chart"
                if label == self.titles[0]:
                    self.scope_uuid = message["uuid"]
            elif kind == "GuiMarkdownMessage":
                self.kinds[message["uuid"]] = "markdown (readouts, status, tables)"
            elif kind == "GuiSliderMessage" and self.move.label and label.startswith(self.move.label):
                self.slider = message["uuid"]
            elif kind == "GuiDropdownMessage" and label == "Exercise" and self.switch_to is not None:
                self.answers.append({"type": "GuiUpdateMessage", "uuid": message["uuid"],
                                     "updates": {"value": self.switch_to}})
                self.switch_to = None
            elif kind == "GuiButtonMessage" and label in self.beacons_clicked():   # as the browser's beacons
                self.answers.append({"type": "GuiUpdateMessage", "uuid": message["uuid"], "updates": {"value": True}})
            return "GUI set-up"
        if kind.startswith("Scene") or kind.endswith("SceneNodeMessage") or "Mesh" in kind or "Label" in kind:
            return "3D view"
        return kind

    def receive(self, frame: bytes, now: float) -> None:
        self.received_bytes += len(frame)
        self.frame_times.append(now)
        messages, lengths, compressed = decode_frame(frame)
        sizes = [len(msgspec.msgpack.encode(m)) for m in messages] if self.breakdown else None
        total = sum(sizes) if sizes else 0
        for index, message in enumerate(messages):
            if message["type"] == "LocalStorageGetItemRequestMessage":   # a browser with nothing stored
                self.answers.append({"type": "LocalStorageGetItemResponseMessage", "value": None,
                                     "error": None, "request_uuid": message["request_uuid"]})
            kind = self._kind(message)
            if (message["type"] == "GuiUpdateMessage" and message["uuid"] == self.scope_uuid
                    and "data" in message["updates"]):
                self.scope_times.append(now)
            self.read_readout(message, now)
            if self.breakdown:
                share = compressed * sizes[index] / total if total else 0.0
                self.kind_bytes[kind] += share + _binary_bytes(message, lengths)
                self.kind_count[kind] += 1
        if self.breakdown:
            self.kind_bytes["frame headers and padding"] += len(frame) - compressed - sum(lengths)

    def read_readout(self, message: dict, now: float) -> None:
        content = (message.get("updates") or message.get("props") or {}).get("_markdown")   # viser's name
        found = self.move.readout_row.search(content) if isinstance(content, str) else None
        if found is None or found.group(1) == self.readout:
            return
        if self.moved_at is not None and self.readout is not None:
            self.latencies.append((now, now - self.moved_at))
            self.moved_at = None
        self.readout = found.group(1)

    def latencies_in(self, start: float, end: float) -> list[float]:
        """Slider-to-readout latencies [s] of the readouts that arrived in [start, end)."""
        return [latency for arrival, latency in self.latencies if start <= arrival < end]

    async def _inputs(self, outbox: asyncio.Queue, stop: asyncio.Event) -> None:
        """A camera message at once and then, like a student, every few seconds a camera
        message, and every third time also a slider move."""
        turn = 0
        await asyncio.sleep(random.uniform(0.0, 0.2))
        while not stop.is_set():
            angle = 0.1 * turn
            camera = {"type": "ViewerCameraMessage", "wxyz": [1.0, 0.0, 0.0, 0.0],
                      "position": [0.3 + angle, 0.3, 0.3], "fov": 1.0, "near": 0.01, "far": 100.0,
                      "image_height": 768, "image_width": 386, "look_at": [0.0, 0.0, 0.0],
                      "up_direction": [0.0, 0.0, 1.0]}
            outbox.put_nowait(camera)
            if self.slider is not None and self.slider_every and turn % self.slider_every == self.slider_every - 1:
                outbox.put_nowait({"type": "GuiUpdateMessage", "uuid": self.slider,
                                   "updates": {"value": self.move.values[turn // self.slider_every % 2]}})
                self.moved_at = time.perf_counter()
            turn += 1
            with contextlib.suppress(asyncio.TimeoutError):
                await asyncio.wait_for(stop.wait(), CAMERA_PERIOD_S * random.uniform(0.8, 1.2))

    async def _write(self, connection, outbox: asyncio.Queue) -> None:
        """The tab's only writer: like a browser, whose socket sends never hold up its reading,
        the reader only queues its answers here."""
        while True:
            await connection.send(msgspec.msgpack.encode(await outbox.get()))

    async def run(self, stop: asyncio.Event) -> None:
        try:
            async with websockets.asyncio.client.connect(
                    self.url, subprotocols=[PROTOCOL], max_size=None, compression=None,
                    open_timeout=60) as connection:
                self.connected = True
                self.worker = connection.response.headers.get(WORKER_HEADER)
                outbox: asyncio.Queue = asyncio.Queue()
                helpers = [asyncio.create_task(self._inputs(outbox, stop)),
                           asyncio.create_task(self._write(connection, outbox))]
                try:
                    while not stop.is_set():
                        try:
                            frame = await asyncio.wait_for(connection.recv(), 0.5)
                        except TimeoutError:
                            continue
                        self.receive(frame, time.perf_counter())
                        while self.answers:
                            outbox.put_nowait(self.answers.pop(0))
                        if helpers[1].done():                # the writer failed: its error ends the tab
                            helpers[1].result()
                finally:
                    for helper in helpers:
                        helper.cancel()
                    await asyncio.gather(*helpers, return_exceptions=True)
                self.closed = "stopped"
        except websockets.ConnectionClosed as error:
            self._ended(_closing(error))
        except (TimeoutError, OSError, websockets.WebSocketException) as error:
            self._ended(f"connection error: {type(error).__name__}: {error}")
        except Exception as error:  # noqa: BLE001 - a frame the tab could not read ends it, with the reason
            self._ended(f"reader exception: {type(error).__name__}: {error}")

    def _ended(self, why: str) -> None:
        self.closed, self.ended_at = why, time.perf_counter()

    def beacons_clicked(self) -> tuple[str, ...]:
        """The beacon buttons a browser on ``panel`` clicks: that panel shown, and the Scope hidden."""
        return (f"{SHOWN_LABEL} {self.panel}",) + (() if self.watches_scope else (f"{HIDDEN_LABEL} {SCOPE}",))

    @property
    def watches_scope(self) -> bool:
        """Whether the tab shows the Scope (else its scope is hidden and gets no updates)."""
        return self.panel == SCOPE

    def longest_gap(self, start: float, end: float) -> tuple[float, float, float]:
        """(seconds, start, end) of the longest time without a scope update in [start, end) (without
        any message, for a tab on another panel)."""
        arrivals = [start] + [t for t in (self.scope_times if self.watches_scope else self.frame_times)
                              if start <= t < end] + [end]
        return max((b - a, a, b) for a, b in itertools.pairwise(arrivals))

    def stall(self, start: float, end: float, limit_s: float | None = None) -> str | None:
        """Why the tab stalled in [start, end): it ended early, or no scope update came for more
        than ``limit_s`` (default ``STALL_S``; then whether any message came in the longest such
        gap, and whether the gap lasted to the end: a silent connection, not a slow server), or,
        on another panel, no message for more than ``STALL_AWAY_S``; None if it did not."""
        if self.ended_at is not None and self.ended_at < end:
            return self.closed
        if limit_s is None:
            limit_s = STALL_S if self.watches_scope else STALL_AWAY_S
        gap_s, gap_start, gap_end = self.longest_gap(start, end)
        if gap_s <= limit_s:
            return None
        frames = sum(gap_start < t < gap_end for t in self.frame_times)
        until = " until the end of the window" if gap_end == end else ""   # else it streamed again
        why = (f"messages but no scope update for {gap_s:.1f} s{until} ({frames} frames)" if frames
               else f"no message at all for {gap_s:.1f} s{until}")
        if gap_start > start:
            return why
        before = [t for t in self.scope_times if t < start]        # the window began in the gap
        last_frame = max((t for t in self.frame_times if t < start), default=None)
        if not before:
            return why + f"; no scope update since it opened ({len(self.frame_times)} frames in all)"
        return why + (f"; before the window {len(before)} scope updates, the last {start - before[-1]:.1f} s "
                      f"before it, the last message {start - last_frame:.1f} s before it")

    def rate(self, start: float, end: float) -> float:
        """Scope updates per second in [start, end)."""
        return sum(start <= t < end for t in self.scope_times) / (end - start)


# -- the measurement ---------------------------------------------------------------

async def _measure(url: str, steps: list[int], window_s: float, server_pid: int, new_tab,
                   report, all_steps: bool) -> tuple[list[Step], list[Tab]]:
    """``new_tab(url, k)``: the k-th tab."""
    stop = asyncio.Event()
    tabs: list[Tab] = []
    tasks: list[asyncio.Task] = []
    results: list[Step] = []
    try:
        for clients in steps:
            while len(tabs) < clients:
                tab = new_tab(url, len(tabs))
                tabs.append(tab)
                tasks.append(asyncio.create_task(tab.run(stop)))
                await asyncio.sleep(1.0 / CONNECT_RATE_PER_S)
            await _settle(tabs)
            pids = process_tree(server_pid)
            server_cpu, own_cpu = cpu_seconds(pids), cpu_seconds([os.getpid()])
            received = [t.received_bytes for t in tabs]
            start = time.perf_counter()
            await asyncio.sleep(window_s)
            end = time.perf_counter()
            server_cpu = cpu_seconds(pids) - server_cpu
            own_cpu = cpu_seconds([os.getpid()]) - own_cpu
            rates = [t.rate(start, end) for t in tabs if t.watches_scope] or [0.0]
            rates_bytes = [(t.received_bytes - r) / (end - start) / 1e3 for t, r in zip(tabs, received)]
            step = Step(clients, min(rates), statistics.median(rates), statistics.median(rates_bytes),
                        max(rates_bytes), server_cpu / (end - start), own_cpu / (end - start),
                        sum(t.connected and t.closed is None for t in tabs),
                        sum(round(r * (end - start)) for r in rates), end - start,
                        [x for t in tabs for x in t.latencies_in(start, end)],
                        [{"tab": number, "worker": t.worker, "why": why}
                         for number, t in enumerate(tabs, 1) if (why := t.stall(start, end))],
                        on_scope=sum(t.watches_scope for t in tabs))
            results.append(step)
            report(step)
            if not step.ok and not all_steps:
                break
    finally:
        stop.set()
        await asyncio.gather(*tasks, return_exceptions=True)
    return results, tabs


async def _settle(tabs: list[Tab]) -> None:
    """Wait ``SETTLE_S``, then until every open tab got a scope update in the last second
    (its lab is built and streaming), then ``SETTLE_S`` more for the first analyses; at most
    ``SETTLE_MAX_S`` in all.  Building a tab costs far more than streaming to it, so a step
    measured while tabs are still being built measures the building."""
    began = time.perf_counter()
    await asyncio.sleep(SETTLE_S)
    while time.perf_counter() - began < SETTLE_MAX_S - SETTLE_S:
        now = time.perf_counter()
        if all(t.scope_times and t.scope_times[-1] > now - 1.0 for t in tabs if t.closed is None and t.watches_scope):
            break
        await asyncio.sleep(0.5)
    await asyncio.sleep(min(SETTLE_S, max(0.0, SETTLE_MAX_S - (time.perf_counter() - began))))


def ramp(clients: int, steps: int) -> list[int]:
    """Client counts of the steps up to ``clients``."""
    return sorted({max(1, round(clients * (k + 1) / steps)) for k in range(steps)})


def tab_factory(exercise: str, breakdown: bool, slider_every: int, mix: bool):
    """The tabs' maker: each on ``exercise`` with the Scope shown, or with ``mix`` the k-th on the
    k-th exercise (``registry`` order, in turn) and on ``PANEL_MIX[k + k // exercises]``
    (``app.commands.tab_mix``): each round of the exercises moves the panels on by one, so that
    every exercise has tabs on the Scope (with 12 exercises and the Scope every other panel, the
    Scope tabs of one round are all on the even-numbered exercises)."""
    if not mix:
        titles = scope_titles(exercise)
        return lambda url, k: Tab(url, titles, breakdown, slider_every)
    names = list(registry())
    moves = {name: mix_move(name) for name in names}

    def new_tab(url: str, k: int) -> Tab:
        name = names[k % len(names)]
        return Tab(url, scope_titles(name), breakdown, slider_every, moves[name],
                   switch_to=None if name == exercise else get(name).title, panel=PANEL_MIX[(k + k // len(names)) % len(PANEL_MIX)])
    return new_tab


def run(clients: int, workers: int, steps: int, window_s: float, exercise: str, port: int,
        breakdown: bool, report=lambda step: None, all_steps: bool = False,
        slider_every: int = SLIDER_EVERY, mix: bool = False) -> dict:
    new_tab = tab_factory(exercise, breakdown, slider_every, mix)
    with tempfile.TemporaryDirectory() as scratch:
        log = Path(scratch) / "server.log"
        extra: tuple[str, ...] = ()
        if workers > 1:
            extra = ("--worker-ports", str(port + 1))
        with lab_server(port, workers, exercise, log, extra) as server:
            results, tabs = asyncio.run(_measure(f"ws://127.0.0.1:{port}", ramp(clients, steps), window_s,
                                                 server.pid, new_tab, report, all_steps))
    passing = [s.clients for s in results if s.ok]
    result = {"exercise": "mix" if mix else exercise, "workers": workers, "window_s": window_s,
              "camera_period_s": CAMERA_PERIOD_S, "slider_move_period_s": CAMERA_PERIOD_S * slider_every or None,
              "machine_cores": os.cpu_count(), "load_average_1min": os.getloadavg()[0],
              "steps": [s.row() for s in results],
              "largest_clients_at_min_updates": max(passing, default=0),
              "min_updates_per_s": MIN_UPDATES_PER_S, "target_bytes_per_s": TARGET_BYTES_PER_S}
    if breakdown and tabs:
        seconds = window_s + SETTLE_S
        total = Counter()
        for tab in tabs:
            total.update(tab.kind_bytes)
        # bytes of all received frames, all tabs, whole run: a tab's share per second of the run
        result["bytes_by_kind_per_tab_run"] = {k: round(v / len(tabs)) for k, v in total.most_common()}
        result["breakdown_note"] = (f"bytes per tab over the whole run (~{seconds:.0f} s of steady state "
                                    "plus the start-up messages)")
    return result


#: the options' valid ranges: (option, lowest, highest)
OPTION_RANGES = {"clients": ("--clients", 1, 1000), "workers": ("--workers", 1, 16), "steps": ("--steps", 1, 50),
                 "window_s": ("--window", 1.0, 120.0), "slider_every": ("--slider-every", 0, 100),
                 "runs": ("--runs", 1, 10)}


def held_in_every_run(results: list[dict]) -> dict[int, int]:
    """Per step (tabs): in how many of the runs it held (every tab at the target, none stalled)."""
    held: dict[int, int] = {}
    for result in results:
        for step in result["steps"]:
            held[step["clients"]] = held.get(step["clients"], 0) + bool(step["ok"])
    return held


def check_options(**values) -> None:
    """``ParameterError`` (one line, the valid range) for an option outside ``OPTION_RANGES``."""
    for name, value in values.items():
        option, low, high = OPTION_RANGES[name]
        if not low <= value <= high:
            raise ParameterError(f"{option} {value:g} is out of range: expected {low:g} ... {high:g}")


def main(clients: int, workers: int, steps: int, window_s: float, exercise: str, port: int,
         breakdown: bool, as_json: bool, all_steps: bool = False, slider_every: int = SLIDER_EVERY,
         mix: bool = False, runs: int = 1) -> int:
    """The ramp ``runs`` times, each on a fresh server; a step holds if it held in every run."""
    check_options(clients=clients, workers=workers, steps=steps, window_s=window_s, slider_every=slider_every,
                  runs=runs)

    def report(step: Step) -> None:
        if not as_json:
            print_step(step)

    if not as_json:
        moves = f"a slider move every ~{CAMERA_PERIOD_S * slider_every:.0f} s" if slider_every else "no slider moves"
        print(f"{'every exercise and panel (--mix)' if mix else exercise}: {workers} worker(s), "
              f"up to {clients} headless tabs ({moves}) (load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores at start)", flush=True)
    results = []
    for number in range(1, runs + 1):
        if runs > 1 and not as_json:
            print(f"run {number} of {runs}:", flush=True)
        try:
            results.append(run(clients, workers, steps, window_s, exercise, port, breakdown, report, all_steps,
                               slider_every, mix))
        except RuntimeError as error:
            print(f"error: {error}", file=sys.stderr)
            return 1
        if not as_json:
            print_summary(results[-1])
    if as_json:
        print(json.dumps(results[0] if runs == 1 else {"runs": results, "steps_held": held_in_every_run(results)},
                         indent=2))
    elif runs > 1:
        print("each step over the runs: " + "; ".join(f"{tabs} tabs held in {held} of {runs}"
                                                      for tabs, held in held_in_every_run(results).items()))
    return 0
