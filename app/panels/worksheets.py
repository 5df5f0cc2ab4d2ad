"""Worksheets with their paper-vs-lab table filled in from the exercise's claims.

A worksheet's marker line (``<!-- claims -->``) becomes the claims table
(``lab_modules.claims.markdown_table``).  Measuring the claims takes seconds,
so the first request shows the table with "…" and starts the measurement in
one background process (niced, so the lab's own threads keep the cores); the
values are cached per exercise for the life of the server, and every tab
waiting for them gets the filled-in worksheet through its callback.
"""

from __future__ import annotations

import concurrent.futures
import multiprocessing
import os
import threading
import time
from collections.abc import Callable
from pathlib import Path

from app.panels.typeset import typeset
from lab_modules.claims import markdown_table, render_worksheet
from lab_modules.evaluation.measured_claims import measure
from lab_modules.exercises import Exercise, get, registry

STATIC = Path(__file__).resolve().parents[2] / "static"
PARENT_CHECK_S = 1.0            # how often the measuring process checks that the server still runs
NICENESS = 19                   # the measuring process yields to the tabs (and anything else) on the machine

_lock = threading.Lock()
_measured: dict[str, list[float]] = {}                      # exercise name -> claim values
_waiting: dict[str, list[Callable[[str], None]]] = {}       # exercise name -> callbacks (measurement under way)
_executor: concurrent.futures.ProcessPoolExecutor | None = None


def _worker_start(server_pid: int) -> None:
    """In the background process: yield the CPU, and exit when the server is gone
    (a killed server must not leave its measuring process behind)."""
    try:
        os.nice(NICENESS)
    except OSError:
        pass

    def watch() -> None:
        while os.getppid() == server_pid:
            time.sleep(PARENT_CHECK_S)
        os._exit(0)
    threading.Thread(target=watch, name="server-watch", daemon=True).start()


def _measure(name: str) -> list[float]:
    """In the background process: the exercise's claim values (NaN where a metric fails)."""
    exercise = get(name)
    return [float("nan") if row.value is None else row.value for row in measure([exercise], quick=True)]


def text(exercise: Exercise, values: list[float] | None = None) -> str:
    """The worksheet with its claims table (``values`` None: "…" in the lab column), other
    exercises named by their titles and its formulas typeset (``app.panels.typeset``)."""
    sheet = (STATIC / "worksheets" / exercise.worksheet).read_text(encoding="utf-8")
    return typeset(titled(render_worksheet(sheet, markdown_table(exercise.claims, values, exercise.parameters))))


def titled(sheet: str) -> str:
    """Exercises a worksheet names by their internal name (`ekf_disturbance`) named as the
    Exercise chooser lists them, so a student finds them there (issue 25)."""
    for name, other in registry().items():
        sheet = sheet.replace(f"`{name}`", f"*{other.title}*")
    return sheet


def current(exercise: Exercise) -> str:
    """The worksheet as far as it is measured now (never waits)."""
    with _lock:
        values = _measured.get(exercise.name)
    return text(exercise, values)


def when_measured(exercise: Exercise, callback: Callable[[str], None]) -> None:
    """Call ``callback(worksheet text)`` once the claims are measured: at once if they
    are, otherwise from a background thread when the measurement ends."""
    global _executor
    with _lock:
        values = _measured.get(exercise.name)
        if values is None:
            first = exercise.name not in _waiting
            _waiting.setdefault(exercise.name, []).append(callback)
            if first:
                if _executor is None:
                    _executor = concurrent.futures.ProcessPoolExecutor(
                        max_workers=1, mp_context=multiprocessing.get_context("spawn"), initializer=_worker_start,
                        initargs=(os.getpid(),))
                future = _executor.submit(_measure, exercise.name)
                future.add_done_callback(lambda done, e=exercise: _finished(e, done))
    if values is not None:
        callback(text(exercise, values))


def _finished(exercise: Exercise, future: concurrent.futures.Future) -> None:
    global _executor
    try:
        values = future.result()
    except Exception:  # noqa: BLE001 -- the process died (e.g. server shutdown) or the run failed: retry next time
        with _lock:
            _waiting.pop(exercise.name, None)
            _executor = None
        return
    with _lock:
        _measured[exercise.name] = values
        callbacks = _waiting.pop(exercise.name, [])
    sheet = text(exercise, values)
    for callback in callbacks:
        try:
            callback(sheet)
        except Exception:  # noqa: BLE001, S110 -- a tab closed meanwhile must not stop the others
            pass
