"""A tab's worker thread: every event of the tab, in order, newest action per control.

The GUI callbacks run on viser's event loop and only ``post`` what to do under a key
(a control): a burst of updates of one slider costs one action, exercise switches are
serialised and never overlap, and one busy tab never occupies threads the others need.
A per-tab ``CpuBudget`` pauses a tab that asks for more than its share of a core.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from app.infra.traffic import callback

#: One tab's worker and analyses together may use this share of a core on average, after a
#: burst of ``TAB_CPU_BURST_S`` of CPU time: a tab that asks for more (a flood of slider
#: updates) waits, with its requests coalescing, and the other tabs keep their share.
TAB_CPU_SHARE = 0.15
TAB_CPU_BURST_S = 1.0


class CpuBudget:
    """A token bucket of CPU seconds shared by one tab's threads."""

    def __init__(self, share: float = TAB_CPU_SHARE, burst_s: float = TAB_CPU_BURST_S):
        self.share, self.burst_s = share, burst_s
        self.allowance, self.refilled = burst_s, time.perf_counter()
        self.lock = threading.Lock()

    def charge(self, cpu_s: float) -> float:
        """Book ``cpu_s``; returns how long the tab should now wait [s] (0: within its share)."""
        with self.lock:
            now = time.perf_counter()
            self.allowance = min(self.burst_s, self.allowance + (now - self.refilled) * self.share) - cpu_s
            self.refilled = now
            return max(0.0, -self.allowance / self.share)


class TabClosed(Exception):
    """The tab closed while something (its lab being built) was under way."""


class TabWorker:
    """The thread that runs one tab's events."""

    def __init__(self, name: str):
        self.name = name
        self.closed = False
        self.budget = CpuBudget()
        self.events: dict[object, Callable[[], None]] = {}   # control -> what to do (newest wins)
        self.wakeup = threading.Condition()
        self.before_event: Callable[[], None] = lambda: None   # runs on the event loop before a post
        self.thread: threading.Thread | None = None

    def start(self, run: Callable[[], None]) -> None:
        self.thread = threading.Thread(target=run, name=self.name, daemon=True)
        self.thread.start()

    def post(self, key, action: Callable[[], None]) -> None:
        """Queue ``action``; it replaces a queued action of the same ``key`` (safe from any
        thread, including viser's event loop)."""
        with self.wakeup:
            if self.closed:
                return
            self.events.pop(key, None)
            self.events[key] = action
            self.wakeup.notify()

    def on(self, key, action: Callable[[], None]):
        """A GUI callback that queues ``action`` under ``key`` (runs on the event loop, returns
        at once), after ``before_event`` (e.g. a value still being typed into a box)."""
        def queue(_event) -> None:
            self.before_event()
            self.post(key, action)
        return callback(queue)

    def next_events(self, due: Callable[[], float | None]) -> list[Callable[[], None]] | None:
        """Wait for events, or until ``due()`` (a perf_counter time, None: never) has come;
        the queued actions, or None once the tab closed."""
        with self.wakeup:
            while not self.events and not self.closed and not self.is_due(due()):
                deadline = due()
                self.wakeup.wait(None if deadline is None else max(deadline - time.perf_counter(), 0.0))
            if self.closed:
                return None
            events, self.events = list(self.events.values()), {}
            return events

    @staticmethod
    def is_due(deadline: float | None) -> bool:
        return deadline is not None and time.perf_counter() >= deadline

    def pace(self, spent_cpu_s: float, condition: threading.Condition | None = None) -> None:
        """Charge ``spent_cpu_s`` to the tab; beyond its share, wait (or until the tab closes)."""
        seconds = self.budget.charge(spent_cpu_s)
        condition = condition or self.wakeup
        if seconds > 0:
            with condition:
                condition.wait_for(lambda: self.closed, seconds)

    def check_open(self) -> None:
        if self.closed:
            raise TabClosed

    def close(self) -> None:
        self.closed = True
        with self.wakeup:
            self.events.clear()
            self.wakeup.notify()
