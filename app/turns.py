"""Analyses take turns: one at a time in a lab process, in the order the tabs asked.

A slider move costs an analysis (kalman_noise: the filter's Riccati equation,
the largest gain factors, the consistency run, the margins: ~0.15 s of CPU).
Analyses are Python and small matrices, so they hold the interpreter lock; two
of them at once are not faster than one after the other.  But every one that
runs competes for that lock with the frame threads that stream every tab's scope:
with 50 tabs each moving a slider every ~9 s, five or six analyses ran at
once and the scopes fell from 25 to 3 updates/s.  With turns, the frame
threads and one analysis share the lock: the scopes keep streaming and, when
the class asks for more analyses than the process can compute, the readouts
arrive later instead (each tab's newest request replaces its older one, so a
queue never holds more than one analysis per tab).

First come, first served: the turn passes straight to the thread that has
waited longest, so a tab whose analysis yields several results does not keep
the turn from the others between them.

After a slider move the readouts come first: an exercise's quick first result
(kalman_noise: 15 ms) does not wait for a turn.  Then the scopes: a turn (for
the fuller results and the margins) starts only once streaming has caught up.
While streaming runs behind (the frame threads start
a round late, or viser's event loop, which encodes and sends every tab's
messages, fires its timers late: then it merges a chart's queued updates and
the tabs get fewer), the thread whose turn it is waits (at most
``MAX_YIELD_S`` per step, so analyses always move on) and streaming catches up.
A tab that asks for a newer analysis leaves the queue (``abandon``): its thread
answers the new request with its quick result at once, not after a turn.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import threading
import time
from collections.abc import Callable, Iterator

YIELD_STEP_S = 0.005             # a turn's holder looks again this often whether the frames caught up ...
MAX_YIELD_S = 1.0                # ... for at most this long
LAG_PROBE_S = 0.02               # the event loop's timer is probed this often ...
MAX_LOOP_LAG_S = 0.015           # ... and runs behind when it fires this much late (a frame is 40 ms)


class LoopLag:
    """How late an asyncio event loop fires a timer: how far behind its work it runs."""

    def __init__(self) -> None:
        self.lag_s = 0.0

    def watch(self, loop: asyncio.AbstractEventLoop) -> None:
        """Probe ``loop`` from now on (it runs in another thread)."""
        asyncio.run_coroutine_threadsafe(self._probe(), loop)

    async def _probe(self) -> None:
        while True:
            due = time.perf_counter() + LAG_PROBE_S
            await asyncio.sleep(LAG_PROBE_S)
            self.lag_s = max(0.0, time.perf_counter() - due)

    def behind(self) -> bool:
        return self.lag_s > MAX_LOOP_LAG_S


class Turns:
    """A lock handed on in the order it was asked for; its holder starts once ``yield_to()``
    is False (or after ``MAX_YIELD_S``)."""

    def __init__(self, yield_to: Callable[[], bool] = lambda: False) -> None:
        self.yield_to = yield_to
        self._lock = threading.Lock()
        self._waiting: collections.deque[threading.Event] = collections.deque()
        self._held = False

    @contextlib.contextmanager
    def turn(self, wake: threading.Event, abandon: Callable[[], bool] = lambda: False) -> Iterator[bool]:
        """Hold the turn for the ``with ... as held`` block.  ``wake`` is the asking thread's own
        event: the holder sets it to hand the turn on, and whoever makes ``abandon()`` True sets
        it too (the tab asked for a newer analysis).  ``held`` is False when it was abandoned
        first: then the block does nothing, and the tab's thread is free for the new request at
        once instead of after a turn."""
        if not self._queue(wake, abandon):
            yield False
            return
        try:
            give_up = time.perf_counter() + MAX_YIELD_S
            while self.yield_to() and not abandon() and time.perf_counter() < give_up:
                time.sleep(YIELD_STEP_S)
            yield not abandon()
        finally:
            with self._lock:
                if self._waiting:
                    self._waiting.popleft().set()     # still held: it changes hands
                else:
                    self._held = False

    def _queue(self, wake: threading.Event, abandon: Callable[[], bool]) -> bool:
        """Wait in line for the turn; False (out of the line) if ``abandon()`` came first."""
        with self._lock:
            if not self._held:
                self._held = True
                return True
            self._waiting.append(wake)
        while True:
            with self._lock:
                wake.clear()                          # before the checks: a later set is not lost
                if wake not in self._waiting:         # handed on to this thread
                    return True
                if abandon():
                    self._waiting.remove(wake)
                    return False
            wake.wait()
