"""Analyses take turns (app/tab/turns.py), and the bench reads the slider-to-readout latency."""

from __future__ import annotations

import threading
import time

import pytest

from app.commands.load_bench import Tab
from app.tab.turns import Turns


def _queue_up(shared: Turns, names: list[str], order: list[str], hold_s: float = 0.02) -> list[threading.Thread]:
    """Threads asking for the turn in the order of ``names`` (each after the previous one waits)."""
    threads = []
    for name in names:
        def work(name=name):
            with shared.turn(threading.Event()):
                order.append(name)
                time.sleep(hold_s)
        thread = threading.Thread(target=work)
        thread.start()
        deadline = time.perf_counter() + 2
        while len(shared.waiting_line) <= len(threads) and time.perf_counter() < deadline:   # this one waits too
            time.sleep(0.001)
        threads.append(thread)
    return threads


def test_the_turn_goes_to_whoever_asked_first():
    shared, order = Turns(), []
    with shared.turn(threading.Event()):               # held: everyone queues behind it
        threads = _queue_up(shared, ["a", "b", "c", "d", "e"], order)
        assert order == []                             # nobody runs while it is held
    for thread in threads:
        thread.join(5)
    assert order == ["a", "b", "c", "d", "e"]
    with shared.turn(threading.Event()):               # free again: taken at once
        pass


def test_an_error_inside_a_turn_hands_it_on():
    shared = Turns()
    with pytest.raises(RuntimeError), shared.turn(threading.Event()):
        raise RuntimeError("an analysis failed")
    done = threading.Event()

    def next_one():
        with shared.turn(threading.Event()):
            done.set()
    threading.Thread(target=next_one).start()
    assert done.wait(2)


def test_a_waiting_thread_whose_work_is_moot_leaves_the_queue_at_once():
    shared, order, moot = Turns(), [], threading.Event()
    outcome = {}

    wake = threading.Event()

    def superseded():
        with shared.turn(wake, abandon=moot.is_set) as held:
            outcome["held"] = held
            if held:
                order.append("superseded")

    with shared.turn(threading.Event()):
        first = _queue_up(shared, ["a"], order)
        waiting = threading.Thread(target=superseded)
        waiting.start()
        deadline = time.perf_counter() + 2
        while len(shared.waiting_line) < 2 and time.perf_counter() < deadline:
            time.sleep(0.001)
        later = _queue_up(shared, ["b"], order)
        started = time.perf_counter()
        moot.set()                                     # the tab asked for a newer analysis ...
        wake.set()                                     # ... and woke its analysis thread
        waiting.join(2)
        assert time.perf_counter() - started < 0.2 and outcome == {"held": False}
        assert len(shared.waiting_line) == 2               # a and b still wait, in order
    for thread in first + later:
        thread.join(5)
    assert order == ["a", "b"]


def _readouts(value: str) -> dict:
    return {"type": "GuiUpdateMessage", "uuid": "r",
            "updates": {"_markdown": f"| quantity | value | unit |\n|---|---:|---|\n"
                                     f"| RMS displacement, measured feedback | {value} | µm |\n"}}


def test_the_bench_times_a_slider_move_to_its_new_readout():
    tab = Tab("ws://unused", ("Rotor position [µm]",))
    tab.read_readout(_readouts("0.47"), now=1.0)      # the first readouts: nothing was moved
    tab.moved_at = 2.0
    tab.read_readout(_readouts("0.47"), now=2.1)      # the scope-window rows refreshed: not the answer
    tab.read_readout(_readouts("0.61"), now=2.3)
    tab.read_readout(_readouts("0.47"), now=2.5)      # no move pending: no latency
    assert tab.latencies == [(2.3, pytest.approx(0.3))]
    assert tab.latencies_in(2.0, 3.0) == [pytest.approx(0.3)] and tab.latencies_in(0.0, 2.0) == []
