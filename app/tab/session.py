"""One browser tab's lab: its own exercise, simulation, parameters, seed and views.

A ``LabSession`` builds the GUI of any exercise generically from the exercise's
parameters, charts, analysis and optional 3D scene, and is made of small parts, each
with its own state set in its constructor:

* ``TabWorker`` (``worker.py``): every event of the tab on one thread, newest per control;
* ``TokenGate`` (``gate.py``): the class token, before anything else is built;
* ``SavedExperiments`` (``saved.py``): autosave, restore on reload, Save and Open;
* ``LabState`` (``state.py``): the running exercise, values, simulation and scope buffer;
* ``Controls`` (``controls.py``): sliders, typed values and the line under a refused one;
* ``AnalysisView`` (``analysis_view.py``): readouts, pole map and plots on their own thread;
* ``Stream`` (``streaming.py``): the simulation's frames on the shared frame clock;
* the panels of ``app.panels``: docks, scope charts, live plots, status, inspector,
  export, actions, worksheets.

Each exercise shown in the tab is one *generation*: switching exercises starts a new one,
and the frames and analyses of an older generation stop writing to the tab (its GUI
handles are gone).  A tab closed while its lab is being built stops building.
"""

from __future__ import annotations

import functools
import itertools
import sys
import threading
import time
import traceback
import weakref
from collections.abc import Callable

import viser

from app.infra import layout
from app.infra.access import Limits
from app.infra.store import Store
from app.panels import entry, filter_branch, page, page_query, scope, worksheets
from app.panels.actions import ActionPanel
from app.panels.docks import Docks
from app.panels.export import ExportButtons, add_download
from app.panels.filter_debugger import FilterDebugger
from app.panels.inspector import FilterInspector
from app.panels.live import LivePlots
from app.panels.plots import plot_chart
from app.panels.scene_view import SceneView
from app.panels.scope_charts import TIME_AXES, ScopeCharts, time_axis_choice
from app.panels.status import PAUSED, RUNNING, SimulationStatus, stopped
from app.panels.text import escaped
from app.tab.analysis_view import AnalysisView
from app.tab.assignment import AssignmentTab
from app.tab.controls import Controls
from app.tab.gate import TokenGate
from app.tab.instructor import InstructorTab
from app.tab.saved import SavedExperiments
from app.tab.state import LabState
from app.tab.streaming import Problems, Stream
from app.tab.worker import TabClosed, TabWorker
from lab_modules.exercises import Exercise, registry
from lab_modules.parameters import Parameter, ParameterError

#: An exercise switch waits this long between the last chart update and the removals: a busy browser
#: (a slow laptop; Chromium with its CPU slowed fourfold in the tests) gathers the messages of a long
#: frame into one batch, and 0.3 s was not always enough there.  (A render request would be an exact
#: barrier, but a browser whose 3D canvas has no size logs an error answering it.)
SETTLE_BEFORE_REMOVAL_S = 1.0
FULL = ("### The lab is full\n\nEvery place on this lab server is taken. This tab enters by itself as soon "
        "as a place is free; or try again in a minute, or ask your instructor.")


class LabSession:
    """The lab in one browser tab."""

    def __init__(self, client: viser.ClientHandle, exercise: Exercise, store: Store | None = None,
                 token: str | None = None, on_refused: Callable[[str], None] | None = None,
                 limits: Limits | None = None, address: str = "unknown", instructor_token: str | None = None):
        """Cheap: the lab is built on the tab's worker thread (after the class token, if one is set,
        and once ``limits.admission`` has a place for it); ``address``: where the tab comes from;
        ``instructor_token`` opens the instructor page of an assignment (``?instructor=CODE``)."""
        self.client = client
        self.exercises = registry()
        self.token = token
        self.limits, self.address = limits, address
        self.admission = limits.admission if limits is not None else None
        self.on_refused = on_refused or (lambda _reason: None)   # disconnects the tab (too many wrong tokens)
        self.gui_lock = threading.RLock()         # writes to the GUI handles; held while the GUI is rebuilt
        self.generations = itertools.count()
        self.generation = next(self.generations)
        self.worker = TabWorker(f"tab-{client.client_id}")
        self.state = LabState()
        self.saved = SavedExperiments(store, client, self.gui_lock, self.state.snapshot, self.worker,
                                      self._show_error, limits.code_tries if limits is not None else None, address)
        self.controls = Controls(self.worker, self.state, self.gui_lock, self._apply)
        self.assignment = AssignmentTab(store, client, self.gui_lock, self.worker, self.state, self._switch,
                                        limits.code_tries if limits is not None else None, address)
        self.instructor = InstructorTab(store, client, self.gui_lock, self.worker, instructor_token, self._leave_lab,
                                        self.on_refused, limits.token_tries if limits is not None else None, address)
        self.worker.before_event = self.controls.flush_typing
        self.analysis = AnalysisView(client, self.gui_lock, self.state, self.worker, self._current)
        self.docks = Docks()
        self.scene_view = SceneView()
        self.status = SimulationStatus(client)
        self.problems = Problems(self.gui_lock, self._show_problem)
        self.gate: TokenGate | None = None
        self.scene = None                         # the exercise's 3D view (None: it has none)
        self.stream: Stream | None = None
        self.inspector: FilterInspector | None = None
        self.debugger: FilterDebugger | None = None
        self.upload_note = None                   # what its upload button did
        self.time_axis = TIME_AXES[0]             # the scope's time axis, the student's choice for every exercise
        # the browser reports the 3D view's size with every camera update (also on a resize)
        client.camera.on_update(lambda _camera: self.post("canvas", self._fit_scene))
        self.worker.start(lambda: self._work(exercise))

    @property
    def closed(self) -> bool:
        return self.worker.closed

    # -- the tab's worker: every event, in order, newest value per control ----------------
    def post(self, key, action: Callable[[], None]) -> None:
        """Queue ``action`` for the worker (safe from any thread, including viser's event loop)."""
        self.worker.post(key, action)

    def _work(self, exercise: Exercise) -> None:
        try:
            with self.gui_lock:
                self.worker.check_open()
                self.client.gui.configure_theme(dark_mode=False, show_logo=False, control_width="large")
                # shadow passes made every scene update costly
                self.client.scene.configure_default_lights(cast_shadow=False)
                self.client.scene.configure_environment_map(hdri=None)
                if self.token is None:
                    self._start_restored(exercise)
                else:
                    self.gate = TokenGate(self.client.gui, self.token, self.worker, lambda: self._enter(exercise),
                                          self.on_refused, self.limits and self.limits.token_tries, self.address)
            while (events := self.worker.next_events(lambda: self.saved.autosave_due)) is not None:
                spent = time.thread_time()
                for action in events:
                    self._do(action)
                if self.worker.is_due(self.saved.autosave_due):
                    self._do(self._autosave)
                self.worker.pace(time.thread_time() - spent)
        except TabClosed:
            pass
        finally:
            self.close()
            if self.saved.autosave_due is not None:
                self._do(self._autosave)          # the last changes of a closed tab

    def _do(self, action: Callable[[], None]) -> None:
        """Run one event; an error is shown in the tab (one line), never ends the worker."""
        try:
            action()
        except TabClosed:
            raise
        except Exception as error:  # noqa: BLE001 - any failure of one event is shown, the tab goes on
            traceback.print_exc()
            try:
                self._show_error(f"⚠️ That did not work: {escaped(error) or type(error).__name__}")
            except RuntimeError:                  # the line's GUI is gone: the log has it, the tab goes on
                traceback.print_exc()

    def _enter(self, exercise: Exercise) -> None:
        """The class token was right: the lab replaces the gate."""
        with self.gui_lock:
            self.client.gui.reset()
            self._start_restored(exercise)

    # -- life cycle ------------------------------------------------------------------
    def _wait_for_a_place(self) -> None:
        """Hold the tab at a "the lab is full" note until the process has a place for its lab."""
        if self.admission is None or self.admission.try_enter(self):
            return
        note = self.client.gui.add_markdown(FULL)
        if not self.admission.wait_to_enter(self, lambda: self.closed):
            raise TabClosed
        note.remove()

    def _start_restored(self, exercise: Exercise) -> None:
        """Start the experiment this browser autosaved last (a reloaded tab gets its work back),
        else ``exercise`` on its defaults (call holding ``gui_lock``), once the lab has a place."""
        self._wait_for_a_place()
        page_query.add(self.client.gui, self._on_query, self.worker.on)   # the link's ?assignment=CODE
        saved = self.saved.browser_autosave(self.exercises)
        if saved is not None:
            recording = (saved.recording_name, saved.recording) if saved.recording is not None else None
            try:
                self._start(self.exercises[saved.exercise], saved.parameters, recording)
            except (ParameterError, ValueError) as error:    # saved by an older lab: its defaults instead
                print(f"autosave {saved.code} not restored: {error}", file=sys.stderr, flush=True)
            else:
                self.saved.restored_from = saved.code
                self.saved.show_codes()
                return
        self._start(exercise)

    def _start(self, exercise: Exercise, overrides: dict | None = None,
               recording: tuple[str, bytes] | None = None) -> None:
        """Show ``exercise`` (call holding ``gui_lock``): at ``overrides`` and with ``recording``
        (a saved experiment), else on its defaults."""
        self.worker.check_open()
        data = exercise.load_data(*recording) if recording else None
        values = exercise.resolve({**(overrides or {}), "data": data})
        self.state.load(exercise, values, exercise.simulation(values), recording)
        self.scene = exercise.scene(self.state.values)
        self._build_gui(exercise)
        self.controls.follow_ranges(exercise)
        self.controls.follow_values(exercise)
        self.worker.check_open()
        if self.scene is not None:
            self.scene.attach(self.client.scene)
            self._fit_scene(attached=True)
        self.worker.check_open()
        self._request_analysis()
        self.stream.start()
        self.saved.changed()

    def _switch(self, exercise: Exercise, overrides: dict | None = None,
                recording: tuple[str, bytes] | None = None) -> None:
        """Replace the tab's lab (on the worker, so switches never overlap)."""
        self._stop_lab()
        with self.gui_lock:
            self.worker.check_open()
            self.status.clear_card()              # the old exercise's stop message goes with it
            layout.clear(self.client.gui, keep=self.docks.kept())   # docks stay
            self.client.scene.reset()
            self._start(exercise, overrides, recording)

    def _on_query(self, fields: dict[str, str]) -> None:
        """The page's query string, as the browser reported it (``app/panels/page_query.py``)."""
        if fields.get("assignment"):
            self.assignment.offer(fields["assignment"], self._show_error)
        elif "instructor" in fields:
            self.instructor.offer(fields["instructor"], self._show_error)
        elif fields.get("experiment") and self.saved.saved_note is not None:
            self.saved.open(fields["experiment"], self.exercises, self._switch)

    def _stop_lab(self) -> None:
        """The shown exercise's frames and analyses stop writing; their last updates go out."""
        with self.gui_lock:
            self.generation = next(self.generations)  # the old frames and analyses stop writing
        if self.stream is not None:
            self.stream.join(timeout=2.0)
        # The browser applies the chart updates of a message batch after its removals (and then
        # reports updates of removed charts): let the last updates go out in a batch of their own.
        self.client.flush()
        time.sleep(SETTLE_BEFORE_REMOVAL_S)

    def _leave_lab(self) -> None:
        """The tab stops its lab for another page (the instructor's): the GUI and 3D view go."""
        self._stop_lab()
        with self.gui_lock:
            self.state.running = False
            self.client.gui.reset()
            self.client.scene.reset()
            self.scene = None                     # nothing left to fit to the window
            self.controls.forget_error_line()

    def _choose(self, title: str) -> None:
        chosen = next((e for e in self.exercises.values() if e.title == title), None)
        if chosen is not None and chosen is not self.state.exercise:   # the traffic refuses unknown titles
            self._switch(chosen)

    def _current(self, generation: int) -> bool:
        """Whether ``generation`` still owns the tab's GUI (call holding ``gui_lock``)."""
        return generation == self.generation and not self.worker.closed

    def close(self) -> None:
        """Stop the worker, simulation and analysis threads; the tab is gone (idempotent, any thread)."""
        self.worker.close()
        self.analysis.close()
        if self.admission is not None:
            self.admission.leave(self)            # also wakes this tab if it waits for a place

    def report(self, text: str) -> None:
        """A one-line message for the tab from outside (e.g. a message the server refused)."""
        self.post(("report", text), lambda: self._show_error(f"⚠️ {escaped(text)}"))

    def _show_error(self, markdown: str) -> None:
        with self.gui_lock:
            if self.state.exercise is not None and not self.closed and self.controls.error is not None:
                self.controls.error.content = markdown

    def _show_problem(self, markdown: str) -> None:
        if not self.closed and self.controls.error is not None:
            self.controls.error.content = markdown

    def _autosave(self) -> None:
        if self.state.exercise is None:
            self.saved.autosave_due = None
            return
        self.saved.autosave()

    # -- GUI ---------------------------------------------------------------------
    def _build_gui(self, exercise: Exercise) -> None:
        gui, on, values = self.client.gui, self.worker.on, self.state.values
        chooser = gui.add_dropdown("Exercise", tuple(e.title for e in self.exercises.values()),
                                   initial_value=exercise.title,
                                   hint="Switch this tab to another exercise (starts it on its defaults).")
        chooser.on_update(on("exercise", lambda: self._choose(chooser.value)))
        # beside the chooser: Open switches the exercise, and its note is in view wherever it lands
        self.saved.add_folder(gui, on, lambda code: self.saved.open(code, self.exercises, self._switch))
        self.saved.show_codes()
        gui.add_markdown(f"### {exercise.title}")
        self.assignment.add_panel(gui, exercise)  # a student's assignment: Submit and the results
        self.status.add_line(gui)
        buttons = gui.add_button_group("Simulation", ("Run", "Pause", "Reset"))
        buttons.on_click(on("buttons", lambda: self._on_button(buttons.value)))
        self.status.add_speed(gui)                # filled in while it runs
        self.controls.add_error_line(gui)         # under the buttons, in view (not at the foot of the controls)
        self.inspector = FilterInspector.add(gui, self.state.simulation, on("inspector step", self._step_one))
        self.debugger = FilterDebugger.add(gui, self.state.simulation, on, keep=lambda q, r, model: filter_branch.keep(
            self.state.exercise, self.state.values_now(), model, q, r, self.controls.follow), scene=self.client.scene,
            rig=self.scene)
        ActionPanel(gui, exercise, on, self.state.values_now, self._still_current(), self.gui_lock,
                    self.worker, self.client, plot_chart)   # the exercise's buttons, if any
        if self.scene is not None:
            self.scene_view.add_control(gui, on)
        toggle = self.docks.add_toggle(gui)
        if exercise.data_description:
            upload = gui.add_upload_button("Load recording (CSV)", icon=viser.Icon.UPLOAD, mime_type=".csv,text/csv",
                                           hint=exercise.data_description)
            upload.on_upload(on("upload", lambda: self._on_upload(upload.value)))
            self.upload_note = gui.add_markdown("")       # what the upload did, right under the button
        if exercise.download_label:
            add_download(gui, exercise, on, self.state.values_now, self.client)
        self.controls.add(gui, exercise, values)
        self.assignment.fix(self.controls.inputs, self.controls.entries, chooser)
        gui.add_html(scope.LEGEND_STYLE)
        gui.add_html(entry.STYLE)
        gui.add_html(page.STYLE)
        gui.add_markdown(page.title_markdown(exercise.title))   # the browser tab's title

        first = self.analysis.first(exercise, values)
        self.docks.dock(gui)
        tabs = self.docks.tabs
        with tabs["Scope"]:
            self.analysis.add_pinned(gui)              # first: in view at 1366 x 768 above any live plot
            live = LivePlots(gui, exercise, self.state.simulation)   # if the exercise has any
            time_axis = time_axis_choice(gui, self.time_axis)
            charts = ScopeCharts(gui, exercise.charts, self.state.columns, self.state.window_ms(), self.time_axis)
            time_axis.on_update(on("time axis", lambda: self._set_time_axis(charts, time_axis.value)))
            self.analysis.add_readouts(gui, first)
            ExportButtons.add(gui, exercise, on, self._export_snapshot, self.analysis.export_rows,
                              self.client.send_file_download)   # CSV and PNG for a lab report
        with tabs["Pole map"]:
            self.analysis.add_pole_map(gui, tabs["Pole map"], on)
        with tabs["Analysis"]:
            self.analysis.add_analysis_tab(gui, tabs["Analysis"])
        self.docks.add_worksheets(gui, worksheets.current(exercise))   # claims table filled in as measured
        self.analysis.add_worksheet_beacons(gui, tabs)
        self.stream = Stream(self.client, self.gui_lock, self.state, self.generation, self._current, self.scene,
                             self.scene_view, charts, live, self.status, self.analysis.refresh_live_readouts,
                             self.problems, self.analysis.scope_shown)

        def put_beside() -> None:
            with self.gui_lock:
                self.docks.put_worksheet_beside(gui, toggle.value)
        toggle.on_update(on("beside", put_beside))

        def measure_claims(asked: list = []) -> None:   # noqa: B006 - once per exercise shown
            if not asked:
                asked.append(True)
                # The claims may take minutes to measure: a tab closed meanwhile must not be kept alive for them.
                worksheets.when_measured(exercise, functools.partial(LabSession._show_measured, weakref.proxy(self),
                                                                     self.generation))
        self.analysis.on_worksheet = measure_claims
        if self.docks.worksheet_beside:
            measure_claims()                      # the worksheet floats beside the charts: in view

    def _show_measured(self, generation: int, sheet: str) -> None:
        """The worksheet with its claims measured, if ``generation`` still owns the tab."""
        with self.gui_lock:
            if self._current(generation):
                self.docks.show_worksheet(sheet)

    def _set_time_axis(self, charts: ScopeCharts, time_axis: str) -> None:
        """The scope's time axis, kept for the tab's next exercises too."""
        self.time_axis = time_axis
        with self.gui_lock, self.docks.tabs["Scope"]:
            if not self.closed and self.stream is not None and self.stream.scope is charts:
                charts.set_time_axis(self.client.gui, time_axis, self.state.window_ms())
                self.stream.draw(time.perf_counter())   # also while paused

    def _fit_scene(self, attached: bool = False) -> None:
        """Fold the 3D view away while the window leaves it no room (a cut-off strip at 1024 x 768), show
        it again once there is (``attached``: its scene is new)."""
        with self.gui_lock:
            if self.scene is not None and not self.closed:
                camera = self.client.camera
                self.scene_view.fit(self.client.scene, camera.image_width, camera.image_height, attached)

    def _still_current(self) -> Callable[[], bool]:
        """Whether the generation being built still owns the tab (for parts that run on threads)."""
        generation = self.generation
        return lambda: self._current(generation)

    def _export_snapshot(self) -> tuple:
        """The scope buffer, values, column names and experiment code, for an export."""
        with self.state.lock:
            return self.state.buffer.copy(), dict(self.state.values), tuple(self.state.columns), \
                self.saved.autosave_code

    # -- events --------------------------------------------------------------------
    def _apply(self, parameter: Parameter, value) -> None:
        """A parameter took ``value``: the analysis, the simulation (retuned or restarted) and
        the 3D view follow."""
        lab = self.state
        self.scene_view.hold()
        with lab.lock:
            lab.values[parameter.name] = value
        self.saved.changed()
        if parameter.name == "time_scale":
            return
        self._request_analysis()                  # readouts first: they are what the student watches
        with lab.lock:
            restart = lab.restart_after(parameter.name)
            if not restart:
                step_s = lab.simulation.sample_time_s
                lab.simulation = lab.exercise.retune(lab.simulation, lab.values)
                if lab.simulation.sample_time_s != step_s:
                    lab.buffer = lab.buffer[:0]   # the scope's rows assume one sample time
        if restart:
            self._show_restarted()
        if self.scene is not None:
            try:
                self.scene.update(dict(lab.values))
            except Exception as error:  # noqa: BLE001 - the 3D view is not worth the lab
                self.problems.report("3D view", error)

    def _on_upload(self, uploaded) -> None:
        """Load an uploaded file; the note under the button says what happened (issue 25: it used to
        appear at the foot of the controls, out of view)."""
        lab = self.state
        try:
            data = lab.exercise.load_data(uploaded.name, uploaded.content)
        except ParameterError as error:
            named = str(error) if uploaded.name in str(error) else f"{uploaded.name}: {error}"
            self.upload_note.content = f"⚠️ Not loaded: {escaped(named)}"
            return
        rows = f" {len(data)} rows;" if hasattr(data, "__len__") else ""   # a recording's
        self.upload_note.content = f"✓ Loaded {escaped(uploaded.name)}.{rows} the run starts again with it."
        with lab.lock:
            lab.values["data"] = data
            lab.restart()
        self._show_restarted()
        lab.recording = (uploaded.name, uploaded.content)
        self.controls.follow_ranges(lab.exercise)
        self.saved.changed()
        self._request_analysis()

    def _show_restarted(self) -> None:
        with self.gui_lock:
            if not self.closed:
                self.stream.show_restarted()

    def _on_button(self, which: str) -> None:
        lab = self.state
        with lab.lock:
            if which == "Reset" or which == "Run" and lab.simulation.status_message():
                lab.reset()
            lab.running = which != "Pause"
        with self.gui_lock:
            if which != "Pause" and not self.stream.alive() and not self.closed:
                self.stream.start()               # never left without a simulation
            self.problems.seen.clear()
            self.status.line.content = RUNNING if lab.running else PAUSED
            if not lab.running:
                self.status.speed.content = ""
            self._refresh_inspector()

    def _step_one(self) -> None:
        """The filter inspector's step: pause, advance one sample, draw it and show the filter."""
        message = self.state.step_one()
        with self.gui_lock:
            if self.closed:
                return
            self.status.line.content = (stopped(message) if message
                                        else "**Paused** (stepping one sample at a time)")
            self.stream.draw(time.perf_counter())
            self._refresh_inspector()

    def _refresh_inspector(self) -> None:
        """The inspector shows the filter at the newest sample while paused (call holding ``gui_lock``)."""
        if self.inspector is not None and not self.closed:
            with self.state.lock:
                running, simulation = self.state.running, self.state.simulation
                self.inspector.show(running, simulation)
                if self.debugger is not None:
                    self.debugger.show(running, simulation)

    def _request_analysis(self) -> None:
        """Ask the analysis thread for the current values; a newer request supersedes an older one."""
        self.analysis.ask(self.generation, self.state.exercise, self.state.values_now())
