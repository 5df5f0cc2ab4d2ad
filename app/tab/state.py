"""What one tab is running: the exercise, its values, simulation and scope buffer, under one lock."""

from __future__ import annotations

import threading

import numpy as np

from app.panels import scope
from lab_modules.exercises import Exercise

SCOPE_WINDOW_S = 0.05             # simulated time shown on the scope (at the slowest time scale)
SCOPE_ROWS = 20_000               # most samples the scope keeps


def window_rows(values: dict, sample_time_s: float) -> int:
    """Samples in the scope window at the time scale of ``values``."""
    time_scale = values.get("time_scale", 1.0)
    return min(max(int(SCOPE_WINDOW_S * max(time_scale / 0.01, 1.0) / sample_time_s), 2), SCOPE_ROWS)


class LabState:
    """The running exercise of a tab.  Frames, the worker, actions and the inspector read and
    change it holding ``lock``; the buffer is replaced, the rows it holds never change
    (``scope.ScopeWindow``), so a reader may keep a reference without the lock."""

    def __init__(self):
        self.lock = threading.Lock()
        self.exercise: Exercise | None = None
        self.values: dict = {}
        self.simulation = None
        self.running = False
        self.columns: dict[str, int] = {}        # simulation column -> buffer column
        self.buffer = np.empty((0, 1))            # time [s], then the simulation's columns
        self.window = scope.ScopeWindow()         # where ``buffer`` lives
        self.recording: tuple[str, bytes] | None = None   # the uploaded file, as it came

    def load(self, exercise: Exercise, values: dict, simulation, recording) -> None:
        with self.lock:
            self.exercise, self.values, self.simulation, self.running = exercise, values, simulation, True
            self.columns = {name: 1 + i for i, name in enumerate(simulation.columns)}
            self.buffer = np.empty((0, 1 + len(self.columns)))
        self.recording = recording

    def values_now(self) -> dict:
        with self.lock:
            return dict(self.values)

    def window_rows(self) -> int:
        return window_rows(self.values, self.simulation.sample_time_s)

    def window_ms(self) -> float:
        return self.window_rows() * self.simulation.sample_time_s * 1e3

    def reset(self) -> None:
        """A new run at the current values (call holding ``lock``)."""
        self.simulation = self.exercise.simulation(self.values)
        self.buffer = self.buffer[:0]

    def restart(self) -> None:
        """A new run at the current values, running at once (call holding ``lock``): after a change
        that invalidates the shown run, the scope never keeps a run the readouts no longer describe."""
        self.reset()
        self.running = True

    def restart_after(self, name: str) -> bool:
        """Restart the run after a change of parameter ``name`` where the change invalidates it: a new
        seed, an exercise that replays afresh on every change (``Exercise.restarts_on_change``), a
        stopped run (it touched down: not carried on), also when paused; whether it restarted (call
        holding ``lock``)."""
        if name == "seed" or self.exercise.restarts_on_change or self.simulation.status_message():
            self.restart()
            return True
        return False

    def append(self, trace: np.ndarray) -> None:
        """New samples into the scope window (call holding ``lock``)."""
        self.buffer = self.window.append(self.buffer, trace, self.window_rows())

    def step_one(self) -> str:
        """Pause and advance one sample; the stop message ("" while it holds)."""
        with self.lock:
            self.running = False
            trace = self.simulation.advance(1)
            self.buffer = np.concatenate([self.buffer, trace])[-self.window_rows():]
            return self.simulation.status_message()

    def trace(self) -> dict[str, np.ndarray]:
        """The scope window by column name."""
        with self.lock:
            return {name: self.buffer[:, column] for name, column in self.columns.items()}

    def latest(self) -> dict[str, float]:
        """The newest sample of the scope buffer by column name (empty before the first)."""
        buffer = self.buffer
        if len(buffer) == 0:
            return {}
        row = buffer[-1]
        return {"time_s": float(row[0]), **{name: float(row[column]) for name, column in self.columns.items()}}

    def snapshot(self) -> tuple[str, dict, str | None, bytes | None]:
        """What a saved experiment keeps: exercise, values (without parsed data), recording."""
        with self.lock:
            values = {k: v for k, v in self.values.items() if k != "data"}
        name, content = self.recording or (None, None)
        return self.exercise.name, values, name, content
