"""A tab's saved experiments (app/tab/saved.py) when the database fails, and how often a tab
that keeps changing is autosaved."""

from __future__ import annotations

import threading
import time
from types import SimpleNamespace

from app.infra.store import Store
from app.tab import saved as saved_module
from app.tab.saved import AUTOSAVE_AFTER_S, AUTOSAVE_AT_MOST_S, RETRY_AFTER_S, SavedExperiments
from app.tab.worker import TabWorker
from tests.test_store_access import FullStore, damaged_database


class Note:
    content = ""


RECORDING = b"t,x\n" + b"0.1,0.2\n" * 25_000


def _tab(store):
    """The saved-experiments part of a tab (an experiment with a 200 kB recording) with a browser
    that keeps what it is given."""
    browser = {}
    client = SimpleNamespace(local_storage=SimpleNamespace(set_item=browser.__setitem__))
    shown: list[str] = []
    saved = SavedExperiments(store, client, threading.RLock(), lambda: ("kalman_noise", {"seed": 3}, "r.csv", RECORDING),
                             TabWorker("test"), shown.append)
    saved.autosave_note, saved.saved_note = Note(), Note()
    return saved, shown, browser


def test_a_failing_autosave_says_so_in_the_tab_and_retries_later(tmp_path):
    store = FullStore(tmp_path)
    saved, shown, browser = _tab(store)
    saved.changed()
    waits = []
    for _ in range(len(RETRY_AFTER_S) + 1):
        before = time.perf_counter()
        saved.autosave()
        waits.append(saved.autosave_due - before)
    assert "Your settings are kept in this tab" in shown[-1] and "is full" in shown[-1]
    assert len(shown) == len(RETRY_AFTER_S) + 1 and not browser and saved.autosave_code is None
    assert all(retry <= wait <= retry + 1.0 for wait, retry in zip(waits, RETRY_AFTER_S, strict=False))
    assert waits[-1] >= RETRY_AFTER_S[-1]                     # then every 60 s
    due = saved.autosave_due
    saved.changed()                                           # moving a slider does not hurry the retry
    assert saved.autosave_due == due
    store.make_room()
    saved.autosave()
    assert saved.autosave_code and browser == {"autosave": saved.autosave_code}
    assert shown[-1] == f"Autosaved again as **{saved.autosave_code}**."
    assert store.load(saved.autosave_code).parameters == {"seed": 3} and saved.autosave_due is None


def test_save_and_open_on_a_damaged_database_answer_next_to_the_buttons(tmp_path):
    codes = damaged_database(tmp_path)
    saved, _, _ = _tab(Store(tmp_path))
    saved.save()
    assert saved.saved_note.content.startswith("⚠️ Not saved: ") and "kept in this tab" in saved.saved_note.content
    opened = []
    outcomes = set()
    for code in codes:
        saved.open(code, {"kalman_noise": object()}, lambda *args: opened.append(args))
        outcomes.add(saved.saved_note.content.split(":")[0])
    assert "⚠️ Not opened" in outcomes                         # a damaged page: one line, no exception


def test_a_tab_that_keeps_changing_is_autosaved_every_few_seconds(tmp_path, monkeypatch):
    """A slider moved every 0.25 s for 12 s: autosaved at least every ``AUTOSAVE_AT_MOST_S``
    (waiting for a quiet second alone saved nothing until the moves stopped)."""
    now = [1000.0]
    monkeypatch.setattr(saved_module.time, "perf_counter", lambda: now[0])
    saved, _, _ = _tab(Store(tmp_path))
    saved.changed()
    assert saved.autosave_due == 1000.0 + AUTOSAVE_AFTER_S   # a single change: a second later
    written = []
    for _ in range(48):
        saved.changed()
        now[0] += 0.25
        if saved.autosave_due is not None and saved.autosave_due <= now[0]:
            saved.autosave()
            written.append(now[0])
    gaps = [b - a for a, b in zip([1000.0, *written], written, strict=False)]
    assert len(written) >= 2 and max(gaps) <= AUTOSAVE_AT_MOST_S + 0.25, written


def test_open_is_throttled_per_tab_and_address(tmp_path):
    """Codes that open nothing: a tab may try a few, an address a few more across its tabs;
    beyond, Open waits and does not look the code up (so a good guess teaches nothing)."""
    from app.infra.access import CODE_TRIES_BURST, TAB_CODE_TRIES_BURST, Throttle
    store = Store(tmp_path)
    real = store.save("kalman_noise", {"seed": 1})
    by_address = Throttle("experiment codes", CODE_TRIES_BURST, 10, log=False)
    tabs = []
    for _ in range(3):
        tab, _, _ = _tab(store)
        tab.code_tries, tab.address = by_address, "10.0.0.5"
        tabs.append(tab)
    opened = []
    notes = []
    for tab in tabs:
        for k in range(TAB_CODE_TRIES_BURST + 1):
            tab.open(f"KN-AAAA-BBBB-CC{k:02d}".replace("0", "2").replace("1", "3"), {"kalman_noise": "ex"},
                     lambda *args: opened.append(args))
            notes.append(tab.saved_note.content)
    misses = sum(1 for n in notes if "no experiment is saved" in n)
    assert misses == CODE_TRIES_BURST and notes[TAB_CODE_TRIES_BURST].startswith("⚠️ Too many codes")
    tabs[2].open(real, {"kalman_noise": "ex"}, lambda *args: opened.append(args))
    assert not opened and "Too many codes" in tabs[2].saved_note.content
    fresh, _, _ = _tab(store)                                # another address opens its code at once
    fresh.open(real, {"kalman_noise": "ex"}, lambda *args: opened.append(args))
    assert len(opened) == 1 and fresh.saved_note.content == f"Opened **{real}**."
