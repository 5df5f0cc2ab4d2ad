"""A tab's simulation on the process's shared frame clock (``app.tab.frames``): every frame
advances the simulation by the time passed, draws the scope and live plots, follows with
the 3D view and the readouts of the scope window, and reports a stop."""

from __future__ import annotations

import time
import traceback
from collections.abc import Callable

from app.panels import status as status_texts
from app.panels.live import LivePlots
from app.panels.scene_view import SceneView
from app.panels.scope_charts import ScopeCharts
from app.panels.status import SimulationStatus
from app.panels.text import escaped
from app.tab import frames
from app.tab.state import LabState

LIVE_READOUT_PERIOD_S = 1.0       # the readouts of the scope window follow the running simulation
FRAME_LOCK_WAIT_S = 0.005         # a frame waits this long for its tab's locks, then skips


class Problems:
    """Errors of the simulation thread or the 3D view: each shown once in the tab, logged once."""

    def __init__(self, gui_lock, show: Callable[[str], None]):
        self.gui_lock, self.show = gui_lock, show
        self.seen: set[str] = set()

    def report(self, where: str, error: Exception) -> None:
        text = f"{where}: {type(error).__name__}: {error}"
        if text in self.seen:
            return
        self.seen.add(text)
        traceback.print_exception(error)
        with self.gui_lock:
            self.show(f"⚠️ {escaped(text)} (the simulation goes on)")


class Stream:
    """One exercise's frames in one tab (one generation)."""

    def __init__(self, client, gui_lock, state: LabState, generation: int, is_current: Callable[[int], bool],
                 scene, scene_view: SceneView, scope: ScopeCharts, live: LivePlots, status: SimulationStatus,
                 refresh_readouts: Callable[[], None], problems: Problems,
                 scope_shown: Callable[[], bool]):
        """``scope_shown()``: whether the browser shows the Scope tab; its charts and live plots are
        sent only then (a hidden tab's charts are not drawn: the whole window goes out on return)."""
        self.client, self.gui_lock, self.state = client, gui_lock, state
        self.generation, self.is_current = generation, is_current
        self.scene, self.scene_view, self.scope, self.live = scene, scene_view, scope, live
        self.status, self.refresh_readouts, self.problems = status, refresh_readouts, problems
        self.stop_shown: tuple | None = None       # (message, simulation) of a stop not shown yet
        self.fitted = False                       # the scope's ranges fit the traces of a stopped run
        self.scope_shown = scope_shown
        self.left_out = False                     # frames were not sent while the Scope was hidden
        self.ticker: frames.Ticker | None = None

    def start(self) -> None:
        """Put this generation's simulation on the process's frame clock (``frames.CLOCK``)."""
        self.ticker = frames.CLOCK.add(self._step_function(), name=f"lab-{self.client.client_id}")

    def alive(self) -> bool:
        return self.ticker is not None and self.ticker.is_alive()

    def show_restarted(self) -> None:
        """After a change restarted the run: running again, the stop card gone (call holding ``gui_lock``)."""
        if not self.alive():
            self.start()                          # never left without a simulation
        self.status.clear_card()
        self.status.line.content = status_texts.RUNNING

    def join(self, timeout: float) -> None:
        if self.ticker is not None:
            self.ticker.join(timeout)

    def _step_function(self) -> Callable[[float], bool]:
        """The simulation's frame step: advances, draws and animates until the tab closes or
        shows another exercise; an error in one frame is reported and the next frame goes on."""
        state = [0.0, time.perf_counter(), 0.0, 0.0]      # carry, last frame, next scene, next readouts

        def step(now: float) -> bool:
            if not self.is_current(self.generation):
                return False
            carry, last, next_scene, next_readouts = state
            try:
                # one wake-up of the event loop for the frame's messages (3D view, scope, readouts),
                # not one per message: each wake-up is a system call
                with self.client.atomic():
                    state[0], state[2], state[3] = self._frame(now, now - last, carry, next_scene, next_readouts)
            except Exception as error:  # noqa: BLE001 - reported; the next frame goes on
                self.problems.report("simulation", error)
            state[1] = now
            return True
        return step

    def _frame(self, now: float, elapsed: float, carry: float,
               next_scene: float, next_readouts: float) -> tuple[float, float, float]:
        """One display frame: advance, draw, 3D view; returns the carried state.

        Runs on a frame thread shared with other tabs, so it waits at most
        ``FRAME_LOCK_WAIT_S`` for this tab's locks: while the worker or the analysis holds
        them longer (an exercise being built, a retune), the frame is skipped and the next
        one catches up (the simulated time is carried)."""
        lab = self.state
        if self.scene is not None and self.scene_view.due(now, next_scene) \
                and self.gui_lock.acquire(timeout=FRAME_LOCK_WAIT_S):
            try:                                  # the scene belongs to this generation only
                next_scene = now + self.scene_view.period_s()
                if self.is_current(self.generation):
                    try:
                        self.scene.animate(now, lab.latest())
                    except Exception as error:  # noqa: BLE001 - the 3D view is not worth the simulation
                        self.problems.report("3D view", error)
            finally:
                self.gui_lock.release()
        if lab.running:                           # the simulation's own step: a retune may change it
            carry += lab.values.get("time_scale", 1.0) * elapsed / lab.simulation.sample_time_s
        if not lab.lock.acquire(timeout=FRAME_LOCK_WAIT_S):
            return carry, next_scene, next_readouts
        if not lab.running:
            lab.lock.release()
            if not self.fitted:
                self.fit_ranges(now)
            return 0.0, next_scene, next_readouts
        self.fitted = False
        try:
            steps, carry = int(carry), carry - int(carry)
            meter = self.status.meter
            timed = meter.timed()                 # a CPU-clock read is a system call: not every frame
            started = time.thread_time() if timed else 0.0
            trace = lab.simulation.advance(steps)
            meter.add(steps * lab.simulation.sample_time_s, time.thread_time() - started if timed else None,
                      elapsed)
            lab.append(trace)
            message = lab.simulation.status_message()
            if message:
                lab.running = False
                self.stop_shown = (message, lab.simulation)
        finally:
            lab.lock.release()
        if not self.gui_lock.acquire(timeout=FRAME_LOCK_WAIT_S):
            return carry, next_scene, next_readouts
        try:
            if not self.is_current(self.generation):
                return carry, next_scene, next_readouts
            self.draw(now)
            if now >= next_readouts:
                self.refresh_readouts()
                self.status.speed.content = self.status.meter.text(lab.values.get("time_scale", 1.0))
                next_readouts = now + LIVE_READOUT_PERIOD_S
            stop, self.stop_shown = self.stop_shown, None
            if stop is not None:
                message, stopped = stop
                if lab.simulation is stopped and not lab.running:   # not reset meanwhile
                    self.status.line.content = status_texts.stopped(message)
                    self.status.notify_stop(message)
        finally:
            self.gui_lock.release()
        return carry, next_scene, next_readouts

    def fit_ranges(self, now: float) -> None:
        """Once a run stops or pauses, the scope's y ranges close in on what it shows (while it ran
        they held still and shrank only after ``scope.SHRINK_AFTER_S``: a start-up transient that
        left the window last could keep a range far too wide on the stopped scope)."""
        if not self.scope_shown() or not self.gui_lock.acquire(timeout=FRAME_LOCK_WAIT_S):
            return
        try:
            if self.is_current(self.generation):
                lab = self.state
                self.fitted = self.scope.draw(lab.buffer, lab.simulation.sample_time_s, lab.window_ms(), now,
                                              closed=lambda: not self.is_current(self.generation), fit=True)
                if self.left_out:                 # the live plots too, left out while hidden
                    self.live.draw_next()
                    self.live.draw(lab.simulation, now, self.scope.drawn_until)
                    self.left_out = False
        finally:
            self.gui_lock.release()

    def draw(self, now: float) -> None:
        """The scope and live plots at the newest samples, while the Scope tab is shown (call
        holding ``gui_lock``)."""
        if not self.scope_shown():
            self.left_out = True
            return
        if self.left_out:                         # back on the Scope: the whole window at once
            self.left_out = False
            self.live.draw_next()
        lab = self.state
        self.scope.draw(lab.buffer, lab.simulation.sample_time_s, lab.window_ms(), now,
                        closed=lambda: not self.is_current(self.generation))
        self.live.draw(lab.simulation, now, self.scope.drawn_until)
