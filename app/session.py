"""One browser tab's lab: its own exercise, simulation, parameters, seed and views.

A ``LabSession`` builds the GUI of an exercise generically from the
exercise's parameters, charts, analysis and optional 3D scene, runs the
simulation on its own thread (the compiled loops release the GIL, so tabs run
in parallel) and stops everything when the tab closes.  The exercise chooser
at the top swaps the whole lab for another exercise.

Everything a tab asks for runs on the tab's own *worker* thread, one event at
a time: the GUI callbacks only record which control changed (newest value
wins, so a burst of updates costs one), which serialises exercise switches
and keeps one busy tab from occupying threads the others need.  A tab closed
while its lab is still being built stops building and starts no threads.
"""

from __future__ import annotations

import itertools
import re
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import viser

from app import entry, export, frames, inspector, layout, margins, mode_picker, pole_map, scope, worksheets
from app.access import token_matches
from app.actions import ActionPanel
from app.live import LivePlots, SpeedMeter
from app.store import Store, StoreError
from app.traffic import callback
from app.turns import Turns
from lab_modules.exercises import Analysis, Chart, Exercise, Plot, registry
from lab_modules.parameters import Parameter, ParameterError
from lab_modules.scenes.bearing import CANVAS_PX

STATIC = Path(__file__).resolve().parent.parent / "static"
#: 3D view refresh periods [s] (None: still).  Every scene change makes the viser client
#: render for 250 ms, so anything faster than 4/s renders non-stop: fine on a GPU, but in
#: software WebGL it starves the page (slider-to-readout latency 0.6 s instead of 0.15 s).
SCENE_REFRESH = {"1 update/s": 1.0, "10 updates/s (needs a GPU)": 0.1, "still": None}
SCENE_QUIET_AFTER_INPUT_S = 0.5   # the 3D view holds still this long after a control moves: readouts first
LIVE_READOUT_PERIOD_S = 1.0       # the readouts of the scope window follow the running simulation
SCOPE_WINDOW_S = 0.05             # simulated time shown on the scope (at the slowest time scale)
SCOPE_BUCKETS = 75                # per chart and frame: the extremes of the roughest series in this many
                                  # time buckets, i.e. <= 150 points across the ~500 px plot (see _scope_rows)
ROUGHNESS_ROWS = 200              # newest rows that decide which series is the roughest
SCOPE_ROWS = 20_000               # most samples the scope keeps
CONTROL_WIDTH_PX = 380            # the docked controls (left)
PANEL_WIDTH_PX = 600              # the docked charts (right); of 1366 px, 386 stay for the 3D view and the
                                  # notifications (which open there and would otherwise cover the panel's tabs)
SCOPE_ASPECT = 2.2                # width / height of a scope chart
SETTLE_BEFORE_REMOVAL_S = 0.3     # an exercise switch waits this long between the last chart update and removal
LOG_SCALE = {"distr": 3, "log": 10}   # uPlot's logarithmic scale
LOG_DECADES = 4                   # a logarithmic plot shows at most this many decades
#: What the boxes beside the sliders take (app/entry.py; issue 11, defect 10)
NUMBER_BOX_HINT = ("*Type a value in the box beside a slider: 0.5 or 0,5 or 5e-1. A value outside the slider's "
                   "range (under it) is refused with a note under the box, which shows the value in use again.*")
PANEL_TABS = (("Scope", viser.Icon.WAVE_SINE), ("Pole map", viser.Icon.CHART_DOTS),
              ("Analysis", viser.Icon.CHART_LINE), ("Worksheet", viser.Icon.NOTEBOOK))
AUTOSAVE_AFTER_S = 1.0            # a tab's autosave is written this long after its last change
FRAME_LOCK_WAIT_S = 0.005         # a frame waits this long for its tab's locks, then skips (frames.py)
BROWSER_KEY = "autosave"          # the browser's localStorage keeps its newest autosave code under this key
BROWSER_WAIT_S = 1.0              # a new tab waits at most this long for the browser's answer
TOKEN_ATTEMPTS = 5                # wrong class tokens before a tab is disconnected
TOKEN_RETRY_S = 1.0               # a wrong token waits this long before the next try


#: One tab's worker and analyses together may use this share of a core on average, after a
#: burst of ``TAB_CPU_BURST_S`` of CPU time: a tab that asks for more (a flood of slider
#: updates) waits, with its requests coalescing, and the other tabs keep their share.
TAB_CPU_SHARE = 0.15
TAB_CPU_BURST_S = 1.0


#: The process's analyses take turns (app/turns.py): one at a time shares the interpreter with streaming.
ANALYSIS_TURNS = Turns()


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


class _Closed(Exception):
    """The tab closed while its lab was being built."""


def escaped(text) -> str:
    """Text shown in a Markdown element as typed (file names, error messages): Markdown's
    special characters backslash-escaped, then &, < and > as HTML entities (viser's
    Markdown renders raw HTML)."""
    text = re.sub(r"([\\`*_{}\[\]()#+\-.!|~])", r"\\\1", str(text))
    return text.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")


def _with_range(parameter: Parameter) -> str:
    """A number control's hint: its description and its valid range."""
    return f"{parameter.description.rstrip('.')}. Range: {parameter.valid_range().replace('...', '…')}."


def _cell(text: str) -> str:
    """A readout's label or unit as one Markdown table cell: "|S|max" must not end the cell."""
    return str(text).replace("|", "\\|")


SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def _format(value: float | str) -> str:
    """A readout's value as a student reads it: 3 significant digits, thousands grouped up to 10⁹
    ("480 000"), powers of ten written out beyond ("7.5·10⁻⁸"), a word as it is ("touched down")."""
    if isinstance(value, str):                        # a word instead of a number
        return value
    if np.isnan(value):
        return "—"
    if np.isinf(value):
        return "∞ (unstable)"
    if 1e3 <= abs(value) < 1e9:
        return f"{float(f'{value:.4g}'):,.0f}".replace(",", " ")   # narrow no-break space
    text = f"{value:.3g}"
    if "e" in text:
        mantissa, exponent = text.split("e")
        return f"{mantissa}·10{str(int(exponent)).translate(SUPERSCRIPT)}"
    return text


def _analyses(exercise: Exercise, values: dict) -> Iterator[Analysis]:
    """The results of ``exercise.analyse(values)``, computed as they are asked for: ``analyse``
    returns one ``Analysis`` or yields a quick one, then fuller ones."""
    result = exercise.analyse(values)
    if isinstance(result, Analysis):
        yield result
    else:
        yield from result


class LabSession:
    """The lab in one browser tab.

    Each exercise shown in the tab is one *generation*: switching exercises
    starts a new one, and the simulation thread and analyses of an older
    generation stop writing to the tab (its GUI handles are gone)."""

    def __init__(self, client: viser.ClientHandle, exercise: Exercise, store: Store | None = None,
                 token: str | None = None, on_refused: Callable[[str], None] | None = None):
        """Cheap: the lab is built on the tab's worker thread (after the class token, if one is set)."""
        self.client = client
        self.exercises = registry()
        self.store = store
        self.token = token
        self.on_refused = on_refused or (lambda _reason: None)   # disconnects the tab (too many wrong tokens)
        self.lock = threading.Lock()                  # values, simulation, buffer, running
        self.gui_lock = threading.RLock()             # writes to the GUI handles; held while the GUI is rebuilt
        self.generations = itertools.count()
        self.generation = next(self.generations)
        self.closed = False
        self.exercise: Exercise | None = None
        self.scene_refresh = next(iter(SCENE_REFRESH))   # this tab's choice, kept across exercises
        self.worksheet_beside = False                     # likewise
        self.scene_quiet_until = 0.0                      # perf_counter time before which the 3D view waits
        self.typing: dict[str, entry.Quiet] = {}          # the boxes' waits for typing to stop (rebuilt per exercise)
        self.thread: threading.Thread | None = None
        self.analysis_thread: threading.Thread | None = None
        self.analysis_request: tuple[int, Exercise, dict] | None = None
        self.analysis_wakeup = threading.Condition()
        self.turn_wake = threading.Event()           # this tab's place in line for an analysis turn (app/turns.py)
        self.events: dict[object, Callable[[], None]] = {}   # control -> what to do (newest wins)
        self.wakeup = threading.Condition()
        self.autosave_code: str | None = None
        self.autosave_due: float | None = None               # perf_counter time of the next autosave
        self.recording: tuple[str, bytes] | None = None      # the uploaded file, as it came
        self.problems: set[str] = set()                       # simulation-thread errors already shown
        self.token_attempts = 0
        self.budget = CpuBudget()
        self.worker = threading.Thread(target=self._work, args=(exercise,), name=f"tab-{client.client_id}",
                                       daemon=True)
        self.worker.start()

    # -- the tab's worker: every event, in order, newest value per control ----------------
    def post(self, key, action: Callable[[], None]) -> None:
        """Queue ``action`` for the worker; it replaces a queued action of the same ``key``
        (safe from any thread, including viser's event loop)."""
        with self.wakeup:
            if self.closed:
                return
            self.events.pop(key, None)
            self.events[key] = action
            self.wakeup.notify()

    def _on(self, key, action: Callable[[], None]):
        """A GUI callback that queues ``action`` under ``key`` (runs on the event loop, returns at once),
        after any value still being typed into a box (app/entry.py)."""
        def queue(_event) -> None:
            for typing in list(self.typing.values()):
                typing.now()
            self.post(key, action)
        return callback(queue)

    def _work(self, exercise: Exercise) -> None:
        try:
            with self.gui_lock:
                self._check_open()
                self.client.gui.configure_theme(dark_mode=False, show_logo=False, control_width="large")
                # shadow passes made every scene update costly
                self.client.scene.configure_default_lights(cast_shadow=False)
                self.client.scene.configure_environment_map(hdri=None)
                if self.token is None:
                    self._start_restored(exercise)
                else:
                    self._ask_token(exercise)
            while True:
                with self.wakeup:
                    while not self.events and not self.closed and not self._autosave_now():
                        timeout = None if self.autosave_due is None else \
                            max(self.autosave_due - time.perf_counter(), 0.0)
                        self.wakeup.wait(timeout)
                    if self.closed:
                        break
                    events, self.events = list(self.events.values()), {}
                spent = time.thread_time()
                for action in events:
                    self._do(action)
                if self._autosave_now():
                    self._autosave()
                self._pause(self.budget.charge(time.thread_time() - spent), self.wakeup)
        except _Closed:
            pass
        finally:
            self.close()
            if self.autosave_due is not None:
                self._autosave()                          # the last changes of a closed tab

    def _do(self, action: Callable[[], None]) -> None:
        """Run one event; an error is shown in the tab (one line), never ends the worker."""
        try:
            action()
        except _Closed:
            raise
        except Exception as error:  # noqa: BLE001 - any failure of one event is shown, the tab goes on
            traceback.print_exc()
            self._show_error(f"⚠️ That did not work: {escaped(error)}")

    def _pause(self, seconds: float, condition: threading.Condition) -> None:
        """Wait ``seconds`` (the tab used more than its share), or until the tab closes."""
        if seconds > 0:
            with condition:
                condition.wait_for(lambda: self.closed, seconds)

    def _check_open(self) -> None:
        if self.closed:
            raise _Closed

    # -- class token -------------------------------------------------------------------
    def _ask_token(self, exercise: Exercise) -> None:
        """One field asking for the class token; nothing of the lab is built before it is right."""
        gui = self.client.gui
        gui.add_markdown("### AMB estimation lab\nEnter the class token your instructor gave you.")
        field = gui.add_text("Class token", "", hint="The token shown by the lab's server at start; "
                                                     "then press Enter the lab.")
        enter = gui.add_button("Enter the lab")
        message = gui.add_markdown("")

        def check() -> None:
            """The button, not every keystroke, is a try (the field sends each keystroke: a slow
            typist would use up the tries, and free checks per keystroke would invite guessing)."""
            if self.exercise is not None:                 # already in (a second click)
                return
            if token_matches(self.token, field.value):
                with self.gui_lock:
                    self.client.gui.reset()
                    self._start_restored(exercise)
                return
            self.token_attempts += 1
            if self.token_attempts >= TOKEN_ATTEMPTS:
                self.on_refused("too many wrong class tokens")
                raise _Closed
            time.sleep(TOKEN_RETRY_S)                     # guessing costs time; other tabs are not held up
            message.content = f"⚠️ That is not the class token ({TOKEN_ATTEMPTS - self.token_attempts} tries left)."
        enter.on_click(self._on("token", check))

    # -- life cycle ------------------------------------------------------------------
    def _start_restored(self, exercise: Exercise) -> None:
        """Start the experiment this browser autosaved last (a reloaded tab gets its work back),
        else ``exercise`` on its defaults (call holding ``gui_lock``)."""
        saved = self._browser_autosave()
        if saved is not None:
            recording = (saved.recording_name, saved.recording) if saved.recording is not None else None
            try:
                self._start(self.exercises[saved.exercise], saved.parameters, recording)
            except (ParameterError, ValueError) as error:    # saved by an older lab: its defaults instead
                print(f"autosave {saved.code} not restored: {error}", file=sys.stderr, flush=True)
            else:
                self.restored_from = saved.code
                self._show_codes()
                return
        self._start(exercise)

    def _browser_autosave(self):
        """The saved experiment whose code the browser keeps (``BROWSER_KEY``), or None."""
        if self.store is None:
            return None
        try:
            code = self.client.local_storage.get_item(BROWSER_KEY, timeout=BROWSER_WAIT_S)
        except (RuntimeError, TimeoutError):              # no answer: a headless client, or storage blocked
            return None
        self._check_open()
        if not code:
            return None
        try:
            saved = self.store.load(code)
        except StoreError:
            return None
        return saved if saved.exercise in self.exercises else None

    def _start(self, exercise: Exercise, overrides: dict | None = None,
               recording: tuple[str, bytes] | None = None) -> None:
        """Show ``exercise`` (call holding ``gui_lock``): at ``overrides`` and with ``recording``
        (a saved experiment), else on its defaults."""
        self._check_open()
        data = exercise.load_data(*recording) if recording else None
        values = exercise.resolve({**(overrides or {}), "data": data})
        simulation = exercise.simulation(values)
        with self.lock:
            self.exercise, self.values, self.simulation, self.running = exercise, values, simulation, True
            self.columns = {name: 1 + i for i, name in enumerate(simulation.columns)}
            self.buffer = np.empty((0, 1 + len(self.columns)))
        self.recording = recording
        self.shown_poles: pole_map.PoleView | None = None
        self.shown_analysis: Analysis | None = None   # the last analysis shown, redrawn with fresh scope readouts
        self.scene = exercise.scene(self.values)
        self._build_gui()
        self._follow_ranges()
        self._check_open()
        if self.scene is not None:
            self.scene.attach(self.client.scene)
        self._check_open()
        self._request_analysis()
        if self.analysis_thread is None:
            self.analysis_thread = threading.Thread(target=self._analysis_worker,
                                                    name=f"analysis-{self.client.client_id}", daemon=True)
            self.analysis_thread.start()
        self._start_simulation_thread()
        self._changed()

    def _start_simulation_thread(self) -> None:
        """Put this generation's simulation on the process's frame clock (``frames.CLOCK``)."""
        self.thread = frames.CLOCK.add(self._ticker(self.generation), name=f"lab-{self.client.client_id}")

    def _switch(self, exercise: Exercise, overrides: dict | None = None,
                recording: tuple[str, bytes] | None = None) -> None:
        """Replace the tab's lab (on the worker, so switches never overlap)."""
        with self.gui_lock:
            self.generation = next(self.generations)  # the old thread and analyses stop writing
        if self.thread is not None:
            self.thread.join(timeout=2.0)
        # The browser applies the chart updates of a message batch after its removals (and then
        # reports updates of removed charts): let the last updates go out in a batch of their own.
        self.client.flush()
        time.sleep(SETTLE_BEFORE_REMOVAL_S)
        with self.gui_lock:
            self._check_open()
            self._clear_notification()                # the old exercise's stop message goes with it
            layout.clear(self.client.gui, keep=(self.panel, self.beside, *self.tabs.values()))   # docks stay
            self.client.scene.reset()
            self._start(exercise, overrides, recording)

    def _choose(self, title: str) -> None:
        chosen = next(e for e in self.exercises.values() if e.title == title)
        if chosen is not self.exercise:
            self._switch(chosen)

    def _current(self, generation: int) -> bool:
        """Whether ``generation`` still owns the tab's GUI (call holding ``gui_lock``)."""
        return generation == self.generation and not self.closed

    def close(self) -> None:
        """Stop the worker, simulation and analysis threads; the tab is gone (idempotent, any thread)."""
        self.closed = True
        with self.wakeup:
            self.events.clear()
            self.wakeup.notify()
        with self.analysis_wakeup:
            self.analysis_wakeup.notify()
        self.turn_wake.set()

    def report(self, text: str) -> None:
        """A one-line message for the tab from outside (e.g. a message the server refused)."""
        self.post(("report", text), lambda: self._show_error(f"⚠️ {escaped(text)}"))

    def _show_error(self, markdown: str) -> None:
        with self.gui_lock:
            if self.exercise is not None and not self.closed and hasattr(self, "error"):
                self.error.content = markdown

    # -- saved experiments --------------------------------------------------------------
    def _changed(self) -> None:
        """Something worth keeping changed: autosave after ``AUTOSAVE_AFTER_S`` of quiet."""
        if self.store is not None:
            self.autosave_due = time.perf_counter() + AUTOSAVE_AFTER_S

    def _autosave_now(self) -> bool:
        return self.autosave_due is not None and time.perf_counter() >= self.autosave_due

    def _snapshot(self) -> tuple[str, dict, str | None, bytes | None]:
        with self.lock:
            values = {k: v for k, v in self.values.items() if k != "data"}
        name, content = self.recording or (None, None)
        return self.exercise.name, values, name, content

    def _autosave(self) -> None:
        self.autosave_due = None
        if self.store is None or self.exercise is None:
            return
        try:
            if self.autosave_code is None:
                self.autosave_code = self.store.new_autosave(*self._snapshot())
                self.client.local_storage.set_item(BROWSER_KEY, self.autosave_code)   # for a reload
                self._show_codes()
            else:
                self.store.autosave(self.autosave_code, *self._snapshot())
        except (StoreError, OSError, ValueError) as error:   # sqlite3.Error is not a ValueError: see store
            print(f"autosave failed: {error}", file=sys.stderr, flush=True)

    def _save(self) -> None:
        code = self.store.save(*self._snapshot())
        self.saved_note.content = (f"Saved as **{code}**: type it under *Experiment code* in any tab "
                                   "(also after a restart) and press *Open*.")

    def _open(self, text: str) -> None:
        try:
            saved = self.store.load(text)
            exercise = self.exercises[saved.exercise]
        except (StoreError, KeyError) as error:
            self.saved_note.content = f"⚠️ {escaped(error)}"
            return
        recording = (saved.recording_name, saved.recording) if saved.recording is not None else None
        self._switch(exercise, saved.parameters, recording)
        self.saved_note.content = f"Opened **{saved.code}**."

    def _show_codes(self) -> None:
        with self.gui_lock:
            if hasattr(self, "autosave_note") and not self.closed:
                restored = getattr(self, "restored_from", None)
                lines = [(f"Restored **{restored}**, this browser's last autosave (a new tab or a "
                          "reload continues the newest one).")] if restored else []
                if self.autosave_code is not None:
                    lines.append(f"This tab is autosaved as **{self.autosave_code}**: a reload in this "
                                 "browser brings it back; elsewhere, open that code.")
                self.autosave_note.content = "\n\n".join(lines)

    # -- GUI ---------------------------------------------------------------------
    def _build_gui(self) -> None:
        gui = self.client.gui
        titles = tuple(e.title for e in self.exercises.values())
        chooser = gui.add_dropdown("Exercise", titles, initial_value=self.exercise.title,
                                   hint="Switch this tab to another exercise (starts it on its defaults).")
        chooser.on_update(self._on("exercise", lambda: self._choose(chooser.value)))
        gui.add_markdown(f"### {self.exercise.title}")
        self.status = gui.add_markdown("**Running**")
        buttons = gui.add_button_group("Simulation", ("Run", "Pause", "Reset"))
        buttons.on_click(self._on("buttons", lambda: self._on_button(buttons.value)))
        self.speed, self.speed_meter = gui.add_markdown(""), SpeedMeter()   # filled in while it runs
        inspector.add_controls(self)                  # step one sample, the filter's numbers (app/inspector.py)
        self.action_panel = ActionPanel(self, gui, _plot_chart)   # the exercise's buttons, if any
        if self.scene is not None:
            refresh = gui.add_dropdown("3D view", tuple(SCENE_REFRESH), initial_value=self.scene_refresh,
                                       hint="How often the 3D view follows the simulation. Smooth motion needs "
                                            "a graphics card; without one it slows the whole page.")
            refresh.on_update(self._on("3D view", lambda: setattr(self, "scene_refresh", refresh.value)))
        toggle = gui.add_checkbox("Worksheet beside the charts", self.worksheet_beside,
                                  hint="Show the worksheet in place of the 3D view, next to the scope.")
        if self.exercise.data_description:
            upload = gui.add_upload_button("Load recording (CSV)", icon=viser.Icon.UPLOAD, mime_type=".csv,text/csv",
                                           hint=self.exercise.data_description)
            upload.on_upload(self._on("upload", lambda: self._on_upload(upload.value)))
        if self.exercise.download_label:
            download = gui.add_button(self.exercise.download_label, icon=viser.Icon.DOWNLOAD)
            download.on_click(self._on("download", self._on_download))
            self.download_note = gui.add_markdown("")     # what the button did, where the student looks
        self.inputs: dict[str, viser.GuiInputHandle] = {}
        self.refused: dict[str, bool] = {}            # boxes being put back to the value in use (_refuse)
        self.entries: dict[str, viser.GuiInputHandle] = {}   # typed-value boxes (app/entry.py)
        self.typing = {}
        self.entry_notes: dict[str, viser.GuiMarkdownHandle] = {}   # a refused entry's line, under its box
        groups: dict[str, list[Parameter]] = {}
        for parameter in self.exercise.parameters:
            groups.setdefault(parameter.group, []).append(parameter)
        ranges = self.exercise.parameter_ranges(dict(self.values))   # sliders open on their followed range
        for index, (group, parameters) in enumerate(groups.items()):
            with gui.add_folder(group, expand_by_default=index == 0 or group in ("Controller", "Run")):
                for parameter in parameters:
                    self.inputs[parameter.name] = self._add_input(parameter, ranges.get(parameter.name))
        gui.add_markdown(NUMBER_BOX_HINT)
        gui.add_html(scope.LEGEND_STYLE)
        gui.add_html(entry.STYLE)
        self.error = gui.add_markdown("")
        if self.store is not None:
            with gui.add_folder("Saved experiment", expand_by_default=False):
                self.autosave_note = gui.add_markdown("")
                code = gui.add_text("Experiment code", "", hint="A code such as KN-7Q3M from Save (any tab, "
                                                                 "any day) or from your instructor.")
                actions = gui.add_button_group("Experiment", ("Save", "Open"))
                actions.on_click(self._on("experiment", lambda: self._save() if actions.value == "Save"
                                          else self._open(code.value)))
                self.saved_note = gui.add_markdown("")
            self._show_codes()

        first = next(_analyses(self.exercise, dict(self.values)))
        self.shown_margins = margins.margin_view(self.exercise, dict(self.values))
        first = margins.with_margins(first, self.shown_margins)
        if getattr(self, "panel", None) is None:      # docked once per tab (see app/layout.py)
            self.panel = gui.add_panel()
            self.tabs = {name: self.panel.add_tab(name, icon) for name, icon in PANEL_TABS}
            gui.main_panel.dock_left()                # both panels docked, the 3D view in between
            gui.main_panel.set_width(CONTROL_WIDTH_PX)
            self.panel.dock_right()
            self.panel.set_width(PANEL_WIDTH_PX)
            # The worksheet can also take the 3D view's place, beside the charts (self-paced work).
            self.beside = gui.add_panel(visible=self.worksheet_beside)
            self.tabs["beside"] = self.beside.add_tab("Worksheet", viser.Icon.NOTEBOOK)
            self.beside.float(x=0, y=0, width=CANVAS_PX[0], height=CANVAS_PX[1])   # over the 3D view
            if self.worksheet_beside:
                self.tabs.pop("Worksheet").remove()
        beside = self.beside
        with self.tabs["Scope"]:
            self.window_ms = self._window_rows() * self.simulation.sample_time_s * 1e3
            self.live = LivePlots(gui, self.exercise, self.simulation)   # if the exercise has any
            self.y_ranges = [scope.StickyRange() for _ in self.exercise.charts]
            self.charts = [self._add_chart(chart) for chart in self.exercise.charts]
            self.readouts = gui.add_markdown("*computing …*")
            export.add_buttons(self)                  # CSV and PNG for a lab report (app/export.py)
        with self.tabs["Pole map"]:
            self.shown_poles = pole_map.view(self.exercise, dict(self.values), first.poles)
            self.pole_plots = tuple(gui.add_uplot(data, **options, aspect=1.6)
                                    for data, options in pole_map.charts(self.shown_poles))
            self.mode_picker = mode_picker.ModePicker(gui, self.pole_plots, self.shown_poles)
            self.mode_picker.dropdown.on_update(self._on("show mode", self._pick_mode))
            gui.add_markdown(pole_map.legend_markdown())
            gui.add_markdown("Poles in the s-plane (discrete poles mapped by s = ln z / T); the dashed line is "
                             "the imaginary axis, right of it is unstable. The first map leaves out the fast, "
                             "well-damped poles (sensor lag, amplifier) that squash the second.")
            self.pole_table = gui.add_markdown(pole_map.table_markdown(self.shown_poles))
        with self.tabs["Analysis"]:
            self.plots, self.plot_shapes = [], []
            for plot in first.plots:
                data, options = _plot_chart(plot)
                self.plots.append(gui.add_uplot(data, **options, aspect=2.0))
                self.plot_shapes.append(_plot_shape(plot))
            if not first.plots:
                gui.add_markdown("*This exercise has no analysis plots.*")
        worksheet = worksheets.current(self.exercise)    # claims table filled in as it is measured
        sheets = {}
        if "Worksheet" in self.tabs:
            with self.tabs["Worksheet"]:
                sheets["tab"] = gui.add_markdown(worksheet)
        with self.tabs["beside"]:
            sheets["beside"] = gui.add_markdown(worksheet)

        def show_beside(_event) -> None:
            """The worksheet is in one place at a time: beside the charts or in their tabs."""
            with self.gui_lock:
                self.worksheet_beside = beside.visible = toggle.value
                if toggle.value and "Worksheet" in self.tabs:
                    self.tabs.pop("Worksheet").remove()
                    sheets.pop("tab", None)
                elif not toggle.value and "Worksheet" not in self.tabs:
                    self.tabs["Worksheet"] = self.panel.add_tab(*PANEL_TABS[-1])
                    with self.tabs["Worksheet"]:
                        sheets["tab"] = gui.add_markdown(sheets["beside"].content)
        toggle.on_update(self._on("beside", lambda: show_beside(None)))

        def show_measured(sheet: str, generation: int = self.generation) -> None:
            with self.gui_lock:
                if self._current(generation):
                    for handle in sheets.values():
                        handle.content = sheet
        worksheets.when_measured(self.exercise, show_measured)

    def _add_input(self, parameter: Parameter, span: tuple[float, float] | None = None):
        gui, value = self.client.gui, self.values[parameter.name]
        label = f"{parameter.label} [{parameter.unit}]" if parameter.unit else parameter.label
        if parameter.choices:
            handle = gui.add_dropdown(label, parameter.choices, initial_value=value, hint=parameter.description)
        elif parameter.log:
            # a logarithmic slider (its ends marked in the parameter's unit); the box shows the value
            ends = np.log10(parameter.minimum), np.log10(parameter.maximum)
            handle = gui.add_slider(label, *ends, step=0.001, initial_value=round(float(np.log10(value)), 3),
                                    marks=tuple((end, f"{10 ** end:g}") for end in ends),
                                    hint=f"{_with_range(parameter)} Logarithmic slider.")
        elif parameter.integer:                       # a box only (app/entry.py)
            return self._add_entry(parameter, label, _with_range(parameter))
        else:
            low, high = span if span and span[1] > span[0] else (parameter.minimum, parameter.maximum)
            handle = gui.add_slider(label, low, high,
                                    step=parameter.step or (parameter.maximum - parameter.minimum) / 1000,
                                    initial_value=min(max(float(value), low), high), hint=_with_range(parameter))
        handle.on_update(self._on(("input", parameter.name), lambda p=parameter, h=handle: self._on_input(p, h.value)))
        if not parameter.choices:
            self._add_entry(parameter, "", None)          # beside the slider, in place of its number box
        return handle

    def _add_entry(self, parameter: Parameter, label: str, hint: str | None):
        """The box a value is typed into, read once the student stops typing (app/entry.py)."""
        def still(box) -> None:
            self.post(("typed", parameter.name), lambda: self._on_typed(parameter, box))
        self.entries[parameter.name], self.typing[parameter.name] = entry.add_box(
            self.client.gui, parameter, self.values[parameter.name], label, still, hint)
        self.entry_notes[parameter.name] = self.client.gui.add_markdown("", visible=False)
        return self.entries[parameter.name]

    def _tell(self, name: str | None, markdown: str) -> None:
        """One line for the student: under the box of parameter ``name`` where it has one (where
        the student looks), else at the foot of the controls; "" clears it."""
        for other, note in self.entry_notes.items():
            if other != name and note.visible:
                note.visible = False
        note = self.entry_notes.get(name)
        if note is not None and markdown:
            note.content, note.visible = markdown, True
        self.error.content = "" if note is not None else markdown

    def _follow_ranges(self) -> None:
        """Sliders whose range depends on other values (e.g. the loaded recording's length) span that
        range, the value clamped into it (issue 11, defect 11)."""
        with self.lock:
            values = dict(self.values)
        for name, (low, high) in self.exercise.parameter_ranges(values).items():
            handle = self.inputs.get(name)
            if handle is None or not high > low:
                continue
            handle.min, handle.max = low, high
            clamped = min(max(float(values[name]), low), high)
            if clamped != values[name]:
                handle.value = clamped
                with self.lock:
                    self.values[name] = clamped

    def _add_chart(self, chart: Chart):
        series = [viser.uplot.Series(label="time before now [ms]")]
        if chart.band:
            series += [viser.uplot.Series(label="+3σ", stroke="rgba(214,39,40,0.35)", width=1),
                       viser.uplot.Series(label="−3σ", stroke="rgba(214,39,40,0.35)", width=1)]
        series += [viser.uplot.Series(label=s.label, stroke=s.color, width=1.5) for s in chart.series]
        series += [scope.ANCHOR_SERIES, scope.LAYOUT_SERIES]   # y range held still; axes laid out each frame
        bands = (viser.uplot.Band(series=(1, 2), fill="rgba(214,39,40,0.12)"),) if chart.band else None
        return self.client.gui.add_uplot(
            scope.placeholder(-self.window_ms, 0.0, len(series) - 1), tuple(series),
            title=f"{chart.title} [{chart.unit}]", bands=bands,
            **scope.chart_options("time before now [ms]", f"[{chart.unit}]"),
            scales={"x": viser.uplot.Scale(time=False)}, aspect=SCOPE_ASPECT)

    # -- events --------------------------------------------------------------------
    def _on_typed(self, parameter: Parameter, box) -> None:
        """A value typed into ``parameter``'s box: refused with one line, or set through the slider."""
        with self.gui_lock:
            if self.entries.get(parameter.name) is not box:
                return                                # an earlier exercise's box
        text = box.value
        try:
            value = entry.read(parameter, text)
        except ParameterError as error:
            self._refuse(parameter, entry.refusal(parameter, text, str(error), self.values[parameter.name]))
            return
        self._on_input(parameter, float(np.log10(value)) if parameter.log else value)
        self._put_slider(parameter, value)

    def _on_input(self, parameter: Parameter, shown) -> None:
        value = 10 ** float(shown) if parameter.log else shown
        try:
            value = parameter.parse(value)
        except ParameterError:
            self._refuse(parameter, entry.refusal(parameter, f"{value}", "is out of range",
                                                  self.values[parameter.name]))
            return
        if self.refused.pop(parameter.name, False) and np.isclose(value, self.values[parameter.name], rtol=1e-2):
            return                                    # the box put back by _refuse: its message stays
        entry.show(self.entries.get(parameter.name), value)
        self._tell(None, "")
        self.scene_quiet_until = time.perf_counter() + SCENE_QUIET_AFTER_INPUT_S
        with self.lock:
            self.values[parameter.name] = value
        self._changed()
        if parameter.name == "time_scale":
            return
        self._request_analysis()                      # readouts first: they are what the student watches
        with self.lock:
            if parameter.name == "seed" or self.simulation.status_message():
                self._reset()                         # a stopped run is not carried on (it touched down)
            else:
                step_s = self.simulation.sample_time_s
                self.simulation = self.exercise.retune(self.simulation, self.values)
                if self.simulation.sample_time_s != step_s:
                    self.buffer = self.buffer[:0]     # the scope's rows assume one sample time
        if self.scene is not None:
            try:
                self.scene.update(dict(self.values))
            except Exception as error:  # noqa: BLE001 - the 3D view is not worth the lab
                self._problem("3D view", error)

    def _refuse(self, parameter: Parameter, message: str) -> None:
        """A typed value that sets nothing (letters, empty, beyond the range) is refused, not clamped:
        one line names the parameter, the entry and the range, and the box and slider show the
        value in use again (issue 11, defect 10)."""
        in_use = self.values[parameter.name]
        self._tell(parameter.name, f"⚠️ {escaped(message)}")
        entry.show(self.entries.get(parameter.name), in_use)
        if not parameter.choices:
            self._put_slider(parameter, in_use)

    def _put_slider(self, parameter: Parameter, value) -> None:
        """Move ``parameter``'s slider (if it has one) to ``value``; its echo changes nothing."""
        handle = self.inputs.get(parameter.name)
        shown = float(np.log10(value)) if parameter.log else value
        if handle is not None and handle is not self.entries.get(parameter.name) and handle.value != shown:
            self.refused[parameter.name] = True
            handle.value = shown

    def _on_upload(self, uploaded) -> None:
        try:
            data = self.exercise.load_data(uploaded.name, uploaded.content)
        except ParameterError as error:
            named = str(error) if uploaded.name in str(error) else f"{uploaded.name}: {error}"
            self.error.content = f"⚠️ {escaped(named)}"
            return
        self.error.content = f"Loaded {escaped(uploaded.name)}."
        with self.lock:
            self.values["data"] = data
            self._reset()
        self.recording = (uploaded.name, uploaded.content)
        self._follow_ranges()
        self._changed()
        self._request_analysis()

    def _on_download(self) -> None:
        """Make the file; the note under the button says what happened (issue 11, defect 5: the
        reason a recording failed used to appear below the fold of the left panel)."""
        self.download_note.content = "*Preparing the file …*"
        self.client.flush()
        try:
            filename, content = self.exercise.download(dict(self.values))
        except ParameterError as error:
            self.download_note.content = f"⚠️ {escaped(error)}"
            return
        self.client.send_file_download(filename, content, save_immediately=True)
        self.download_note.content = f"Sent {escaped(filename)} ({len(content) / 1e3:.0f} kB)."

    def _on_button(self, which: str) -> None:
        with self.lock:
            if which == "Reset" or which == "Run" and self.simulation.status_message():
                self._reset()
            self.running = which != "Pause"
        with self.gui_lock:
            if which != "Pause" and (self.thread is None or not self.thread.is_alive()) and not self.closed:
                self._start_simulation_thread()       # never left without a simulation
            self.problems.clear()
            self.status.content = "**Running**" if self.running else "**Paused**"
            if not self.running:
                self.speed.content = ""
            inspector.refresh(self)

    def _reset(self) -> None:
        self.simulation = self.exercise.simulation(self.values)
        self.buffer = self.buffer[:0]

    # -- analysis (readouts, pole map, plots) -----------------------------------
    def _request_analysis(self) -> None:
        """Ask the analysis thread for the current values; a newer request supersedes an older one."""
        with self.analysis_wakeup:
            self.analysis_request = (self.generation, self.exercise, dict(self.values))
            self.analysis_wakeup.notify()
        self.turn_wake.set()                          # an analysis waiting for its turn is moot now

    def _analysis_worker(self) -> None:
        """One analysis at a time per tab, always of the newest values: an analysis
        whose values were superseded stops at its next intermediate result."""
        while True:
            with self.analysis_wakeup:
                while self.analysis_request is None and not self.closed:
                    self.analysis_wakeup.wait()
                if self.closed:
                    return
                (generation, exercise, values), self.analysis_request = self.analysis_request, None
            spent = time.thread_time()
            try:
                results, last, more = _analyses(exercise, values), None, True
                while more:
                    if last is None:                      # the quick first result (the readouts) at once
                        last, more = self._show_next(generation, exercise, values, results, last)
                    else:                                 # the fuller ones take turns
                        with ANALYSIS_TURNS.turn(self.turn_wake, abandon=self._analysis_superseded) as held:
                            last, more = (self._show_next(generation, exercise, values, results, last)
                                          if held else (last, False))
                    self._pause(self.budget.charge(time.thread_time() - spent), self.analysis_wakeup)
                    spent = time.thread_time()
            except (ValueError, ArithmeticError) as error:   # incl. ParameterError, LinAlgError: the tab's
                traceback.print_exc()                         # analyses go on at the next slider move
                with self.gui_lock:
                    if self._current(generation):
                        self.shown_analysis = None        # the message stays until an analysis succeeds
                        self.readouts.content = f"⚠️ The analysis failed at these settings: {error}"

    def _analysis_superseded(self) -> bool:
        return self.analysis_request is not None or self.closed

    def _show_next(self, generation: int, exercise: Exercise, values: dict, results: Iterator[Analysis],
                   last: Analysis | None) -> tuple[Analysis | None, bool]:
        """Show the analysis's next result, or after its last one the last with fresh margins;
        returns the newest result shown and whether to go on."""
        result = next(results, None)
        if result is None:                            # ... the new margins are ready (they take longer)
            if last is not None and self.analysis_request is None:
                fresh = margins.margin_view(exercise, values)
                with self.gui_lock:
                    if self._current(generation):
                        self.shown_margins = fresh
                self._show(generation, margins.with_margins(last, fresh))
            return last, False
        shown = margins.with_margins(result, self.shown_margins)   # the last margins until ...
        if self.analysis_request is not None or not self._show(generation, shown):
            return last, False
        return result, True

    def _update_plots(self, plots) -> None:
        """The Analysis tab's charts show ``plots`` (call holding ``gui_lock``).  A later result of
        ``analyse`` (or the margins appended after it) may hold more, fewer or other plots than the
        first: a chart whose plot changed gets its series, axes and title too, not only the data
        (else its legend and log axes belong to another plot); missing charts are added at the end."""
        for k, plot in enumerate(plots):
            data, options = _plot_chart(plot)
            if k >= len(self.plots):
                with self.tabs["Analysis"]:
                    self.plots.append(self.client.gui.add_uplot(data, **options, aspect=2.0))
                self.plot_shapes.append(_plot_shape(plot))
            elif self.plot_shapes[k] == _plot_shape(plot):
                with self.client.atomic():            # a log axis's ticks follow its range
                    self.plots[k].data, self.plots[k].scales = data, options["scales"]
                    self.plots[k].axes = options["axes"]
            else:
                with self.client.atomic():            # series, axes and data change together
                    handle = self.plots[k]
                    handle.series, handle.axes, handle.data = options["series"], options["axes"], data
                    handle.scales, handle.title = options["scales"], options["title"]
                self.plot_shapes[k] = _plot_shape(plot)
        for handle in self.plots[len(plots):]:
            handle.remove()
        del self.plots[len(plots):], self.plot_shapes[len(plots):]

    def _show(self, generation: int, result: Analysis) -> bool:
        """Show an analysis; False if the tab no longer shows its exercise."""
        with self.gui_lock:
            if not self._current(generation):
                return False
            self.shown_analysis = result
            self.readouts.content = self._readouts_markdown(result)
            self.client.flush()                       # the readouts go out now, not with the next window
            self._update_plots(result.plots)
            exercise, values = self.exercise, dict(self.values)
        poles = pole_map.view(exercise, values, result.poles)   # the root locus: cached per setting
        with self.gui_lock:
            if not self._current(generation):
                return False
            if not poles.same_as(self.shown_poles):
                self.shown_poles = poles
                with self.client.atomic():            # series, axes and data change together
                    self.mode_picker.draw(poles)
                    self.pole_table.content = pole_map.table_markdown(poles)
        return True

    def _pick_mode(self) -> None:
        with self.gui_lock, self.client.atomic():
            self.mode_picker.pick(self.mode_picker.dropdown.value)

    def _readouts_markdown(self, result: Analysis) -> str:
        """The readouts table: the analysis's figures, then the exercise's figures of the scope window."""
        lines = ["| quantity | value | unit |", "|---|---:|---|"]
        lines += [f"| {_cell(label)} | {_format(value)} | {_cell(unit)} |" for label, value, unit in result.readouts]
        with self.lock:
            trace = {name: self.buffer[:, column] for name, column in self.columns.items()}
        if len(next(iter(trace.values()), ())) >= 10:
            lines += [f"| {_cell(label)} (scope window) | {_format(value)} | {_cell(unit)} |"
                      for label, value, unit in self.exercise.live_readouts(trace)]
        return "\n".join(lines) + "\n\n" + "\n\n".join(f"*{n}*" for n in result.notes)

    def _refresh_live_readouts(self) -> None:
        """Redraw the readouts with the scope window's current figures (call holding ``gui_lock``)."""
        if self.shown_analysis is not None:
            readouts = self._readouts_markdown(self.shown_analysis)
            if readouts != self.readouts.content:     # exercises without scope readouts send nothing
                self.readouts.content = readouts

    # -- simulation thread -------------------------------------------------------------
    def _problem(self, where: str, error: Exception) -> None:
        """An error of the simulation thread or the 3D view: shown once in the tab, logged once."""
        text = f"{where}: {type(error).__name__}: {error}"
        if text in self.problems:
            return
        self.problems.add(text)
        traceback.print_exception(error)
        with self.gui_lock:
            if not self.closed and hasattr(self, "error"):
                self.error.content = f"⚠️ {escaped(text)} (the simulation goes on)"

    def _ticker(self, generation: int) -> Callable[[float], bool]:
        """The simulation's frame step on the shared frame clock: advances, draws and animates
        until the tab closes or shows another exercise; an error in one frame is reported and
        the next frame goes on."""
        state = [0.0, time.perf_counter(), 0.0, 0.0]      # carry, last frame, next scene, next readouts

        def step(now: float) -> bool:
            if not self._current(generation):
                return False
            carry, last, next_scene, next_readouts = state
            try:
                # one wake-up of the event loop for the frame's messages (3D view, scope, readouts),
                # not one per message: each wake-up is a system call
                with self.client.atomic():
                    state[0], state[2], state[3] = self._frame(generation, now, now - last, carry,
                                                               next_scene, next_readouts)
            except Exception as error:  # noqa: BLE001 - reported; the next frame goes on
                self._problem("simulation", error)
            state[1] = now
            return True
        return step

    def _frame(self, generation: int, now: float, elapsed: float, carry: float,
               next_scene: float, next_readouts: float) -> tuple[float, float, float]:
        """One display frame: advance, draw, 3D view; returns the carried state.

        Runs on a frame thread shared with other tabs, so it waits at most
        ``FRAME_LOCK_WAIT_S`` for this tab's locks: while the worker or the analysis holds
        them longer (an exercise being built, a retune), the frame is skipped and the next
        one catches up (the simulated time is carried)."""
        period = SCENE_REFRESH[self.scene_refresh]
        if self.scene is not None and period is not None and now >= max(next_scene, self.scene_quiet_until) \
                and self.gui_lock.acquire(timeout=FRAME_LOCK_WAIT_S):
            try:                                  # the scene belongs to this generation only
                next_scene = now + period
                if self._current(generation):
                    try:
                        self.scene.animate(now, self._latest())
                    except Exception as error:  # noqa: BLE001 - the 3D view is not worth the simulation
                        self._problem("3D view", error)
            finally:
                self.gui_lock.release()
        if self.running:                          # the simulation's own step: a retune may change it
            carry += self.values.get("time_scale", 1.0) * elapsed / self.simulation.sample_time_s
        if not self.lock.acquire(timeout=FRAME_LOCK_WAIT_S):
            return carry, next_scene, next_readouts
        try:
            if not self.running:
                return 0.0, next_scene, next_readouts
            steps, carry = int(carry), carry - int(carry)
            timed = self.speed_meter.timed()          # a CPU-clock read is a system call: not every frame
            started = time.thread_time() if timed else 0.0
            trace = self.simulation.advance(steps)
            self.speed_meter.add(steps * self.simulation.sample_time_s,
                                 time.thread_time() - started if timed else None, elapsed)
            window = self._window_rows()
            self.buffer = scope.append(self.buffer, trace, window)
            message = self.simulation.status_message()
            if message:
                self.running = False
                self.stop_shown = (message, self.simulation)
        finally:
            self.lock.release()
        if not self.gui_lock.acquire(timeout=FRAME_LOCK_WAIT_S):
            return carry, next_scene, next_readouts
        try:
            if not self._current(generation):
                return carry, next_scene, next_readouts
            self._draw()
            self.live.draw(self.simulation, now, getattr(self, "drawn_until", None))
            if now >= next_readouts:
                self._refresh_live_readouts()
                self.speed.content = self.speed_meter.text(self.values.get("time_scale", 1.0))
                next_readouts = now + LIVE_READOUT_PERIOD_S
            stop = getattr(self, "stop_shown", None)
            if stop is not None:
                self.stop_shown = None
                message, stopped = stop
                if self.simulation is stopped and not self.running:   # not reset meanwhile
                    self.status.content = f"**Stopped: {message}** Press Run or Reset to start again."
                    self._notify_stop(message)
        finally:
            self.gui_lock.release()
        return carry, next_scene, next_readouts

    def _notify_stop(self, message: str) -> None:
        """One 'Simulation stopped' card at a time: a new stop replaces the last card."""
        self._clear_notification()
        self.notification = self.client.add_notification("Simulation stopped", message, color="red",
                                                         auto_close_seconds=10.0)

    def _clear_notification(self) -> None:
        if getattr(self, "notification", None) is not None:
            self.notification.remove()
            self.notification = None

    def _window_rows(self) -> int:
        """Samples in the scope window at the current time scale."""
        time_scale = self.values.get("time_scale", 1.0)
        T = self.simulation.sample_time_s
        return min(max(int(SCOPE_WINDOW_S * max(time_scale / 0.01, 1.0) / T), 2), SCOPE_ROWS)

    def _latest(self) -> dict[str, float]:
        """The newest sample of the scope buffer by column name (empty before the first)."""
        buffer = self.buffer
        if len(buffer) == 0:
            return {}
        row = buffer[-1]
        return {"time_s": float(row[0]), **{name: float(row[column]) for name, column in self.columns.items()}}

    def _draw(self) -> None:
        """Send the scope charts: only when new samples arrived, as float32, and only the
        rows ``_scope_rows`` picks (the chart's pixel width, not the buffer's length).  Part of the
        frame's one atomic block (``_ticker``)."""
        buffer = self.buffer                          # one reference (replaced, never changed in place)
        if len(buffer) < 2 or buffer[-1, 0] == getattr(self, "drawn_until", None):
            return
        self.drawn_until = buffer[-1, 0]
        sample_time = self.simulation.sample_time_s
        self.window_ms = self._window_rows() * sample_time * 1e3
        if getattr(self, "chart_plans_for", None) is not self.exercise:
            self.chart_plans_for, self.chart_plans = self.exercise, [_chart_plan(c, self.columns)
                                                                     for c in self.exercise.charts]
        # the time axis runs from -window to 0 ms: float32 while that resolves a sample
        float32_time = _float32_resolves(np.array((self.window_ms,)), sample_time * 1e3)
        now = time.perf_counter()
        self.frames_drawn = getattr(self, "frames_drawn", 0) + 1
        for plan, handle, y_range in zip(self.chart_plans, self.charts, self.y_ranges):
            if self.closed:
                return
            t_ms, t32, ys, low, high = frames.chart_frame(buffer, *plan, sample_time, self.window_ms,
                                                          SCOPE_BUCKETS, ROUGHNESS_ROWS)
            y_range.follow(low, high, now)
            data = (t32 if float32_time else t_ms, *ys, scope.anchor(y_range.shown()),
                    scope.layout(self.frames_drawn))
            # Straight to the wire: the handle's ``data`` setter would cast every column to float64.
            handle._impl.props.data = data
            handle._queue_update("data", data)


def _chart_plan(chart: Chart, columns: dict[str, int]) -> tuple:
    """``frames.chart_frame``'s arguments describing ``chart``: its series' buffer columns (for
    the roughness and the values), their scales, the band's (centre, σ) columns or (-1, -1)."""
    series = np.array([columns[s.column] for s in chart.series], dtype=np.int64)
    band = np.array([columns[c] for c in chart.band] if chart.band else (-1, -1), dtype=np.int64)
    return (series, series, np.array([s.scale for s in chart.series], dtype=float), band,
            float(chart.series[0].scale))


def _scope_rows(buffer: np.ndarray, columns: list[int], sample_time_s: float,
                buckets: int = SCOPE_BUCKETS) -> np.ndarray:
    """Rows of the scope buffer to draw: the buffer's time span cut into ``buckets`` buckets
    of whole samples, and in each the rows of the lowest and the highest value of the
    roughest series among ``columns`` (largest mean step), plus the first and last rows.

    Drawn as lines, these points trace the same envelope as every sample (a noisy trace
    stays a band of the same height, a peak keeps its height), with at most ``2 buckets + 2``
    points.  The buckets are aligned to absolute sample numbers, so a sample once chosen
    stays chosen while the trace scrolls (no shimmer).

    The scope draws with the compiled ``frames.scope_rows``; this is its reference."""
    n = len(buffer)
    size = -(-n // buckets)
    if size <= 2:
        return np.arange(n)
    key = buffer[:, 0]
    if len(columns) == 1:
        if np.isfinite(buffer[:, columns[0]]).all():
            key = buffer[:, columns[0]]
    else:
        recent = buffer[-ROUGHNESS_ROWS:, columns]
        finite = np.isfinite(recent).all(axis=0)
        if finite.any():
            roughness = np.where(finite, np.abs(np.diff(recent, axis=0)).sum(axis=0), -1.0)
            choice = buffer[:, columns[int(np.argmax(roughness))]]
            if np.isfinite(choice).all():
                key = choice
    first = round(buffer[0, 0] / sample_time_s)
    lead = first % size
    padded = np.empty(lead + n + (-(lead + n)) % size)
    padded[:lead], padded[lead:lead + n], padded[lead + n:] = key[0], key, key[-1]   # the edge rows' values
    padded = padded.reshape(-1, size)
    base = np.arange(len(padded)) * size - lead
    low, high = base + padded.argmin(axis=1), base + padded.argmax(axis=1)
    rows = np.empty(2 * len(base) + 2, dtype=np.intp)
    rows[0], rows[-1] = 0, n - 1
    rows[1:-1:2], rows[2:-1:2] = np.minimum(low, high), np.maximum(low, high)   # in time order
    np.clip(rows, 0, n - 1, out=rows)
    keep = np.empty(len(rows), dtype=bool)
    keep[0], keep[1:] = True, rows[1:] != rows[:-1]
    return rows[keep]


def _float32_resolves(t_ms: np.ndarray, step_ms: float) -> bool:
    """Whether float32 keeps times ``step_ms`` apart distinct (long runs need float64)."""
    return bool(np.spacing(np.float32(np.abs(t_ms).max())) <= step_ms / 16)


def _plot_shape(plot: Plot) -> tuple:
    """What a chart keeps between data updates: title, axes, series and their scales."""
    return (plot.title, plot.x_label, plot.y_label, plot.log_x, plot.log_y, plot.points,
            tuple((label, color) for label, _, color in plot.series))


def _plot_chart(plot: Plot) -> tuple[tuple, dict]:
    """uPlot arguments of a static analysis plot.  uPlot cannot range over
    NaN gaps, so the y scale gets an explicit range from the finite data."""
    x = np.asarray(plot.x, dtype=float)
    ys = [np.asarray(y, dtype=float) for _, y, _ in plot.series]
    series = (viser.uplot.Series(label=plot.x_label),) + tuple(
        viser.uplot.Series(label=label, stroke=color, width=0,
                           points=viser.uplot.Series_Points(show=True, size=8, fill=color, stroke=color))
        if plot.points else
        viser.uplot.Series(label=label, stroke=color, width=1.5, points=viser.uplot.Series_Points(show=False))
        for label, _, color in plot.series)
    y_span = _log_span(*ys, decades=plot.log_decades or LOG_DECADES) if plot.log_y else _span(*ys)
    return (x, *ys), {
        "series": series, "title": plot.title, "legend": viser.uplot.Legend(live=False),
        "padding": scope.LOG_X_PADDING if plot.log_x else scope.PADDING,
        "axes": (viser.uplot.Axis(label=plot.x_label),
                 viser.uplot.Axis(label=plot.y_label, **(scope.log_axis(y_span["min"], y_span["max"])
                                                         if plot.log_y else {}))),
        "scales": {"x": viser.uplot.Scale(time=False, **(LOG_SCALE if plot.log_x else {})),
                   "y": viser.uplot.Scale(auto=False, **(LOG_SCALE if plot.log_y else {}), **y_span)}}


def _log_span(*arrays: np.ndarray, decades: int = LOG_DECADES) -> dict[str, float]:
    """A logarithmic plot range over the positive finite values of ``arrays`` in whole decades,
    at most ``decades`` of them below the largest value."""
    positive = np.concatenate([a[np.isfinite(a) & (a > 0)] for a in arrays]) if arrays else np.zeros(0)
    if positive.size == 0:
        return {"min": 0.1, "max": 1.0}
    top = np.ceil(np.log10(positive.max()))
    return {"min": 10.0 ** max(np.floor(np.log10(positive.min())), top - decades), "max": 10.0**top}


def _span(*arrays: np.ndarray) -> dict[str, float]:
    """A plot range covering the finite values of ``arrays`` with a 5 % margin."""
    finite = np.concatenate([a[np.isfinite(a)] for a in arrays]) if arrays else np.zeros(0)
    if finite.size == 0:
        return {"min": -1.0, "max": 1.0}
    low, high = float(finite.min()), float(finite.max())
    margin = 0.05 * (high - low) or 0.05 * max(abs(high), 1.0)
    return {"min": low - margin, "max": high + margin}
