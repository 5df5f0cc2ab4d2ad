"""A tab's saved experiments: the autosave (restored by a reload in the same browser), Save
and Open by code, and the notes that tell the student their codes."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable

from app.infra.store import Store, StoreError
from app.panels.text import escaped
from app.tab.worker import TabWorker

AUTOSAVE_AFTER_S = 1.0            # a tab's autosave is written this long after its last change
BROWSER_KEY = "autosave"          # the browser's localStorage keeps its newest autosave code under this key
BROWSER_WAIT_S = 1.0              # a new tab waits at most this long for the browser's answer


class SavedExperiments:
    """Autosave, Save and Open for one tab (``store`` None: the lab runs without a store)."""

    def __init__(self, store: Store | None, client, gui_lock, snapshot: Callable[[], tuple], worker: TabWorker):
        """``snapshot()`` gives (exercise name, values, recording name, recording bytes)."""
        self.store, self.client, self.gui_lock = store, client, gui_lock
        self.snapshot, self.worker = snapshot, worker
        self.autosave_code: str | None = None
        self.autosave_due: float | None = None    # perf_counter time of the next autosave
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
            code = gui.add_text("Experiment code", "", hint="A code such as KN-7Q3M from Save (any tab, "
                                                             "any day) or from your instructor.")
            actions = gui.add_button_group("Experiment", ("Save", "Open"))
            actions.on_click(on("experiment", lambda: self.save() if actions.value == "Save"
                                else open_saved(code.value)))
            self.saved_note = gui.add_markdown(self.opened_note)

    def changed(self) -> None:
        """Something worth keeping changed: autosave after ``AUTOSAVE_AFTER_S`` of quiet."""
        if self.store is not None:
            self.autosave_due = time.perf_counter() + AUTOSAVE_AFTER_S

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
        except (StoreError, OSError, ValueError) as error:   # sqlite3.Error is not a ValueError: see store
            print(f"autosave failed: {error}", file=sys.stderr, flush=True)

    def save(self) -> None:
        code = self.store.save(*self.snapshot())
        self.saved_note.content = (f"Saved as **{code}**: type it under *Experiment code* in any tab "
                                   "(also after a restart) and press *Open*.")

    def open(self, text: str, exercises: dict, switch: Callable[..., None]) -> None:
        """Open the experiment saved as ``text``: ``switch(exercise, parameters, recording)``."""
        try:
            saved = self.store.load(text)
            exercise = exercises[saved.exercise]
        except (StoreError, KeyError) as error:
            self.saved_note.content = f"⚠️ {escaped(error)}"
            return
        recording = (saved.recording_name, saved.recording) if saved.recording is not None else None
        self.opened_note = f"✓ Opened **{saved.code}** ({escaped(exercise.title)})."
        try:
            switch(exercise, saved.parameters, recording)
        finally:
            self.opened_note = ""                 # shown by the new folder, or the switch failed

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
