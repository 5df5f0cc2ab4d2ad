"""A tab's saved experiments: the autosave (restored by a reload in the same browser), Save
and Open by code, and the notes that tell the student their codes.

When the database fails (a full disk, a damaged file), the tab goes on: the failure is one
line in the tab saying that its settings are kept there, and the autosave is tried again
after ``RETRY_AFTER_S`` (growing while it keeps failing); the server log has it once."""

from __future__ import annotations

import math
import time
from collections.abc import Callable

from app.infra.access import TAB_CODE_TRIES_BURST, TAB_CODE_TRIES_PER_MINUTE, Throttle
from app.infra.store import Store, StoreError, StoreUnavailable
from app.panels.text import escaped
from app.tab.worker import TabWorker

AUTOSAVE_AFTER_S = 1.0            # a tab's autosave is written this long after its last change,
AUTOSAVE_AT_MOST_S = 5.0          # and at most this long after its first unsaved change (continuous moves)
RETRY_AFTER_S = (2.0, 5.0, 10.0, 30.0, 60.0)   # a failed autosave is tried again after these, then every 60 s
BROWSER_KEY = "autosave"          # the browser's localStorage keeps its newest autosave code under this key
BROWSER_WAIT_S = 1.0              # a new tab waits at most this long for the browser's answer


class SavedExperiments:
    """Autosave, Save and Open for one tab (``store`` None: the lab runs without a store)."""

    def __init__(self, store: Store | None, client, gui_lock, snapshot: Callable[[], tuple], worker: TabWorker,
                 warn: Callable[[str], None], code_tries: Throttle | None = None, address: str = "unknown"):
        """``snapshot()`` gives (exercise name, values, recording name, recording bytes); ``warn(markdown)``
        shows a line in the tab's error line (a failed autosave); ``code_tries`` counts the codes
        that open nothing per client ``address``, across tabs (this tab has an allowance of its own)."""
        self.store, self.client, self.gui_lock = store, client, gui_lock
        self.snapshot, self.worker, self.warn = snapshot, worker, warn
        self.code_tries, self.address = code_tries, address
        self.tab_code_tries = Throttle("experiment codes", TAB_CODE_TRIES_BURST, TAB_CODE_TRIES_PER_MINUTE, log=False)
        self.autosave_code: str | None = None
        self.autosave_due: float | None = None    # perf_counter time of the next autosave
        self.unsaved_since: float | None = None   # perf_counter time of the first change not yet autosaved
        self.failures = 0                         # autosaves failed in a row
        self.restored_from: str | None = None     # the browser's autosave this tab started from
        self.autosave_note = None                 # the notes in the "Saved experiment" folder
        self.saved_note = None
        self.opened_note = ""                     # what Open did, for the folder of the exercise it opened

    def browser_autosave(self, exercises: dict):
        """The saved experiment whose code the browser keeps (``BROWSER_KEY``), or None."""
        if self.store is None:
            return None
        try:
            code = self.client.local_storage.get_item(BROWSER_KEY, timeout=BROWSER_WAIT_S)
        except (RuntimeError, TimeoutError):      # no answer: a headless client, or storage blocked
            return None
        self.worker.check_open()
        if not code:
            return None
        try:
            saved = self.store.load(code)
        except StoreError:
            return None
        return saved if saved.exercise in exercises else None

    def add_folder(self, gui, on, open_saved: Callable[[str], None]) -> None:
        """The "Saved experiment" folder; ``open_saved(code)`` opens the code typed."""
        if self.store is None:
            return
        # open after an Open: the student sees what it did beside the button they used (issue 25)
        with gui.add_folder("Saved experiment", expand_by_default=bool(self.opened_note)):
            self.autosave_note = gui.add_markdown("")
            code = gui.add_text("Experiment code", "", hint="A code such as KN-7Q3M-X9TA-HPRW from Save (any tab, "
                                                             "any day) or from your instructor.")
            actions = gui.add_button_group("Experiment", ("Save", "Open"))
            actions.on_click(on("experiment", lambda: self.save() if actions.value == "Save"
                                else open_saved(code.value)))
            self.saved_note = gui.add_markdown(self.opened_note)

    def changed(self) -> None:
        """Something worth keeping changed: autosave after ``AUTOSAVE_AFTER_S`` of quiet, or
        ``AUTOSAVE_AT_MOST_S`` after the first unsaved change while the changes go on.  After a
        failure the retry keeps its time: moving a slider does not hammer a failing disk."""
        if self.store is None:
            return
        now = time.perf_counter()
        if self.unsaved_since is None:
            self.unsaved_since = now
        if not self.failures:
            self.autosave_due = min(now + AUTOSAVE_AFTER_S, self.unsaved_since + AUTOSAVE_AT_MOST_S)

    def autosave(self) -> None:
        self.autosave_due = None
        if self.store is None:
            return
        try:
            if self.autosave_code is None:
                self.autosave_code = self.store.new_autosave(*self.snapshot())
                self.client.local_storage.set_item(BROWSER_KEY, self.autosave_code)   # for a reload
                self.show_codes()
            else:
                self.store.autosave(self.autosave_code, *self.snapshot())
        except StoreError as error:               # logged once by the store, not per tab and retry
            self.failures += 1
            retry_s = RETRY_AFTER_S[min(self.failures, len(RETRY_AFTER_S)) - 1]
            self.autosave_due = time.perf_counter() + retry_s
            self.warn(f"⚠️ Autosave failed: {escaped(error)}. Your settings are kept in this tab (do not "
                      f"close it); the lab tries again in {retry_s:.0f} s.")
            return
        self.unsaved_since = None
        if self.failures:
            self.failures = 0
            self.warn(f"Autosaved again as **{self.autosave_code}**.")

    def save(self) -> None:
        try:
            code = self.store.save(*self.snapshot())
        except StoreError as error:
            self.saved_note.content = (f"⚠️ Not saved: {escaped(error)}. Your settings are kept in this tab: "
                                       "press Save again later, or tell your instructor.")
            return
        self.saved_note.content = (f"Saved as **{code}**: type it under *Experiment code* in any tab "
                                   "(also after a restart) and press *Open*.")

    def open(self, text: str, exercises: dict, switch: Callable[..., None]) -> None:
        """Open the experiment saved as ``text``: ``switch(exercise, parameters, recording)``.  Codes
        that open nothing are counted for this tab and its address: beyond their allowance, Open
        waits (so that guessing codes is hopeless)."""
        throttles = [(self.tab_code_tries, "tab")] + ([(self.code_tries, self.address)] if self.code_tries else [])
        wait_s = max(throttle.wait_s(key) for throttle, key in throttles)
        if wait_s > 0:
            self.saved_note.content = (f"⚠️ Too many codes that open nothing: try again in {math.ceil(wait_s)} s "
                                       "(check the code, or ask your instructor).")
            return
        try:
            saved = self.store.load(text)
        except StoreUnavailable as error:
            self.saved_note.content = f"⚠️ Not opened: {escaped(error)}"
            return
        except StoreError as error:               # no such code (or not a code): one try spent
            for throttle, key in throttles:
                throttle.failed(key)
            self.saved_note.content = f"⚠️ Not opened: {escaped(error)}"
            return
        exercise = exercises.get(saved.exercise)
        if exercise is None:
            self.saved_note.content = (f"⚠️ Not opened: {saved.code} is an experiment of "
                                       f"{escaped(saved.exercise)}, which this lab does not have.")
            return
        recording = (saved.recording_name, saved.recording) if saved.recording is not None else None
        self.opened_note = f"Opened **{saved.code}**."
        try:
            switch(exercise, saved.parameters, recording)
        finally:
            self.opened_note = ""                 # shown by the new folder, or the switch failed
        self.saved_note.content = f"Opened **{saved.code}**."   # the new folder's note, or this one's

    def show_codes(self) -> None:
        """The autosave note: where this tab's work was restored from and its autosave code."""
        with self.gui_lock:
            if self.autosave_note is not None and not self.worker.closed:
                self._write_codes()

    def _write_codes(self) -> None:
        lines = [(f"Restored **{self.restored_from}**, this browser's last autosave (a new tab or a "
                  "reload continues the newest one).")] if self.restored_from else []
        if self.autosave_code is not None:
            lines.append(f"This tab is autosaved as **{self.autosave_code}**: a reload in this "
                         "browser brings it back; elsewhere, open that code.")
        self.autosave_note.content = "\n\n".join(lines)
