"""Analyses take turns: one at a time in a lab process, in the order the tabs asked.

A slider move costs an analysis (kalman_noise: the filter's Riccati equation,
the largest gain factors, the consistency run, the margins: ~0.15 s of CPU).
Analyses are Python and small matrices, so they hold the interpreter lock; two
of them at once are not faster than one after the other.  But every one that
runs competes for that lock with the frame threads and with viser's event loop,
which encodes and sends every tab's messages (and, when it falls behind, merges
a chart's queued updates, so the tabs get fewer): with 100 tabs each moving a
slider every ~9 s, a dozen analyses ran at once and the scopes fell from 25 to
1.5 updates/s.  With turns, one analysis shares the lock with streaming.

After a slider move the readouts come first: an exercise's quick first result
(kalman_noise: 15 ms) does not wait for a turn; the fuller results and the
margins do, first come, first served (the turn passes straight to the thread
that has waited longest).  A tab that asks for a newer analysis leaves the line
at once: its thread answers the new request instead of waiting for a turn that
is no longer wanted.
"""

from __future__ import annotations

import collections
import contextlib
import threading
from collections.abc import Callable, Iterator


class Turns:
    """A lock handed on in the order it was asked for."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.waiting_line: collections.deque[threading.Event] = collections.deque()   # wake events, in order
        self._held = False

    @contextlib.contextmanager
    def turn(self, wake: threading.Event, abandon: Callable[[], bool] = lambda: False) -> Iterator[bool]:
        """Hold the turn for the ``with ... as held`` block.  ``wake`` is the asking thread's own
        event: the holder sets it to hand the turn on, and whoever makes ``abandon()`` True sets
        it too (the tab asked for a newer analysis).  ``held`` is False when it was abandoned
        first: then the block does nothing."""
        if not self._queue(wake, abandon):
            yield False
            return
        try:
            yield True
        finally:
            with self._lock:
                if self.waiting_line:
                    self.waiting_line.popleft().set()     # still held: it changes hands
                else:
                    self._held = False

    def _queue(self, wake: threading.Event, abandon: Callable[[], bool]) -> bool:
        """Wait in line for the turn; False (out of the line) if ``abandon()`` came first."""
        with self._lock:
            if not self._held:
                self._held = True
                return True
            self.waiting_line.append(wake)
        while True:
            with self._lock:
                wake.clear()                          # before the checks: a later set is not lost
                if wake not in self.waiting_line:         # handed on to this thread
                    return True
                if abandon():
                    self.waiting_line.remove(wake)
                    return False
            wake.wait()
