"""Every tab's scope frames: a few shared threads per process on the 25 Hz clock.

One thread per tab woke 25 times a second per tab and handed the GIL around between
dozens of threads; here each process has ``FRAME_THREADS`` frame threads, and every
tab is one ``Ticker`` on one of them (the one with the fewest).  A thread calls its
tickers one after the other on an absolute clock; when a round takes longer than a
frame, the next round starts at once and every tab's rate drops alike (the simulation
still follows real time: each tab advances by the time since its own last frame).

What a frame sends is drawn by ``app.panels.scope_charts``.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

FRAME_S = 1 / 25                  # display refresh
FRAME_THREADS = 2                 # frame threads per process (the numba loops release the GIL, so
                                  # two threads use two cores in a single process; more only add hand-offs)


class Ticker:
    """One tab's place on the frame clock: ``step(now)`` is called every frame until it
    returns False (the tab closed or switched).  Quacks like the thread it replaces."""

    def __init__(self, step: Callable[[float], bool], name: str):
        self.step, self.name = step, name
        self.finished = threading.Event()

    def is_alive(self) -> bool:
        return not self.finished.is_set()

    def join(self, timeout: float | None = None) -> None:
        self.finished.wait(timeout)


class _FrameThread:
    def __init__(self, index: int, period_s: float):
        self.period_s = period_s
        self.tickers: list[Ticker] = []
        self.wakeup = threading.Condition()
        self.thread = threading.Thread(target=self._loop, name=f"frames-{index}", daemon=True)
        self.thread.start()

    def add(self, ticker: Ticker) -> None:
        with self.wakeup:
            self.tickers.append(ticker)
            self.wakeup.notify()

    def _loop(self) -> None:
        next_frame = time.perf_counter()
        while True:
            with self.wakeup:
                while not self.tickers:
                    self.wakeup.wait()
                    next_frame = time.perf_counter()
                tickers = tuple(self.tickers)
            next_frame += self.period_s               # a steady rate: the frame's own work is not added
            delay = next_frame - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            else:
                next_frame = time.perf_counter()      # behind (a busy server): no burst of frames to catch up
            finished = []
            for ticker in tickers:
                try:
                    keep = ticker.step(time.perf_counter())
                except Exception:  # noqa: BLE001 - a step reports its own errors; never stop the others
                    keep = True
                if not keep:
                    finished.append(ticker)
            if finished:
                with self.wakeup:
                    self.tickers = [t for t in self.tickers if t not in finished]
                for ticker in finished:
                    ticker.finished.set()


class FrameClock:
    """The process's frame threads (all started on first use)."""

    def __init__(self, threads: int = FRAME_THREADS, period_s: float = FRAME_S):
        self.count, self.period_s = threads, period_s
        self.threads: list[_FrameThread] = []
        self.lock = threading.Lock()

    def add(self, step: Callable[[float], bool], name: str = "tab") -> Ticker:
        """Call ``step(now)`` every frame until it returns False; on the least busy thread."""
        ticker = Ticker(step, name)
        with self.lock:
            if not self.threads:                      # all at once: the thread count stays put from here on
                self.threads = [_FrameThread(index, self.period_s) for index in range(self.count)]
            thread = min(self.threads, key=lambda t: len(t.tickers))
        thread.add(ticker)
        return ticker

    def tabs(self) -> int:
        return sum(len(t.tickers) for t in self.threads)


CLOCK = FrameClock()
