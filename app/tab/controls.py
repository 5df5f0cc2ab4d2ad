"""A tab's parameter controls: a slider (or dropdown) per parameter with a box to type the
value into, one line under the box for a refused value, and sliders whose range follows
other values (e.g. a loaded recording's length)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from app.panels import entry
from app.panels.text import escaped
from app.tab.state import LabState
from app.tab.worker import TabWorker
from lab_modules.exercises import Exercise
from lab_modules.parameters import Parameter, ParameterError

#: What the boxes beside the sliders take (app/panels/entry.py; issue 11, defect 10)
NUMBER_BOX_HINT = ("*Type a value in the box beside a slider: 0.5 or 0,5 or 5e-1. A value outside the slider's "
                   "range (under it) is refused with a note under the box, which shows the value in use again.*")


def with_range(parameter: Parameter) -> str:
    """A number control's hint: its description and its valid range."""
    return f"{parameter.description.rstrip('.')}. Range: {parameter.valid_range().replace('...', '…')}."


class Controls:
    """The controls of a tab, made anew for each exercise it shows; a value taken goes to
    ``apply(parameter, value)``."""

    def __init__(self, worker: TabWorker, state: LabState, gui_lock, apply: Callable[[Parameter, object], None]):
        self.worker, self.state, self.gui_lock, self.apply = worker, state, gui_lock, apply
        self.inputs: dict[str, object] = {}       # parameter -> slider, dropdown or (integers) box
        self.entries: dict[str, object] = {}      # parameter -> the box its value is typed into
        self.typing: dict[str, entry.Quiet] = {}  # the boxes' waits for typing to stop
        self.entry_notes: dict[str, object] = {}  # a refused entry's line, under its box
        self.refused: dict[str, bool] = {}        # sliders being put back to the value in use (refuse)
        self.error = None                         # the line at the foot of the controls

    def flush_typing(self) -> None:
        """Read every box still being typed into now (another control is being used)."""
        for typing in list(self.typing.values()):
            typing.now()

    def add(self, gui, exercise: Exercise, values: dict) -> None:
        """A folder per parameter group, the hint on typed values (call while the GUI is built)."""
        self.inputs, self.entries, self.typing, self.entry_notes, self.refused = {}, {}, {}, {}, {}
        groups: dict[str, list[Parameter]] = {}
        for parameter in exercise.parameters:
            groups.setdefault(parameter.group, []).append(parameter)
        ranges = exercise.parameter_ranges(dict(values))   # sliders open on their followed range
        for index, (group, parameters) in enumerate(groups.items()):
            with gui.add_folder(group, expand_by_default=index == 0 or group in ("Controller", "Run")):
                for parameter in parameters:
                    self.inputs[parameter.name] = self._add_input(gui, parameter, values, ranges.get(parameter.name))
        gui.add_markdown(NUMBER_BOX_HINT)

    def add_error_line(self, gui) -> None:
        self.error = gui.add_markdown("")

    def forget_error_line(self) -> None:
        """The GUI the line was in is gone (the tab left its lab for another page)."""
        self.error = None

    def _add_input(self, gui, parameter: Parameter, values: dict, span: tuple[float, float] | None):
        value = values[parameter.name]
        label = f"{parameter.label} [{parameter.unit}]" if parameter.unit else parameter.label
        if parameter.choices:
            handle = gui.add_dropdown(label, parameter.choices, initial_value=value, hint=parameter.description)
        elif parameter.log:
            # a logarithmic slider (its ends marked in the parameter's unit); the box shows the value
            ends = np.log10(parameter.minimum), np.log10(parameter.maximum)
            handle = gui.add_slider(label, *ends, step=0.001, initial_value=round(float(np.log10(value)), 3),
                                    marks=tuple((end, f"{10 ** end:g}") for end in ends),
                                    hint=f"{with_range(parameter)} Logarithmic slider.")
        elif parameter.integer:                   # a box only (app/panels/entry.py)
            return self._add_entry(gui, parameter, value, label, with_range(parameter))
        else:
            low, high = span if span and span[1] > span[0] else (parameter.minimum, parameter.maximum)
            handle = gui.add_slider(label, low, high,
                                    step=parameter.step or (parameter.maximum - parameter.minimum) / 1000,
                                    initial_value=min(max(float(value), low), high), hint=with_range(parameter))
        handle.on_update(self.worker.on(("input", parameter.name),
                                        lambda p=parameter, h=handle: self.moved(p, h.value)))
        if not parameter.choices:
            self._add_entry(gui, parameter, value, "", None)   # beside the slider, in place of its number box
        return handle

    def _add_entry(self, gui, parameter: Parameter, value, label: str, hint: str | None):
        """The box a value is typed into, read once the student stops typing (app/panels/entry.py)."""
        def still(box) -> None:
            self.worker.post(("typed", parameter.name), lambda: self.typed(parameter, box))
        self.entries[parameter.name], self.typing[parameter.name] = entry.add_box(
            gui, parameter, value, label, still, hint)
        self.entry_notes[parameter.name] = gui.add_markdown("", visible=False)
        return self.entries[parameter.name]

    def tell(self, name: str | None, markdown: str) -> None:
        """One line for the student: under the box of parameter ``name`` where it has one (where
        the student looks), else at the foot of the controls; "" clears it."""
        for other, note in self.entry_notes.items():
            if other != name and note.visible:
                note.visible = False
        note = self.entry_notes.get(name)
        if note is not None and markdown:
            note.content, note.visible = markdown, True
        self.error.content = "" if note is not None else markdown

    def follow_ranges(self, exercise: Exercise) -> None:
        """Sliders whose range depends on other values (e.g. the loaded recording's length) span that
        range, the value clamped into it (issue 11, defect 11)."""
        values = self.state.values_now()
        for name, (low, high) in exercise.parameter_ranges(values).items():
            handle = self.inputs.get(name)
            if handle is None or not high > low:
                continue
            handle.min, handle.max = low, high
            clamped = min(max(float(values[name]), low), high)
            if clamped != values[name]:
                handle.value = clamped
                with self.state.lock:
                    self.state.values[name] = clamped

    def follow_values(self, exercise: Exercise) -> None:
        """Controls of values that follow from the others (``Exercise.following_values``, e.g. the Q22
        a preset searched) show the value in use (issue 25: the box kept a Q22 the filter did not use)."""
        parameters = {p.name: p for p in exercise.parameters}
        for name, value in exercise.following_values(self.state.values_now()).items():
            with self.state.lock:
                self.state.values[name] = value
            entry.show(self.entries.get(name), value)
            self.put_slider(parameters[name], value)

    def typed(self, parameter: Parameter, box) -> None:
        """A value typed into ``parameter``'s box: refused with one line, or set through the slider."""
        with self.gui_lock:
            if self.entries.get(parameter.name) is not box:
                return                            # an earlier exercise's box
        text = box.value
        try:
            value = entry.read(parameter, text)
        except ParameterError as error:
            self.refuse(parameter, entry.refusal(parameter, text, str(error), self.state.values[parameter.name]))
            return
        self.moved(parameter, float(np.log10(value)) if parameter.log else value)
        self.put_slider(parameter, value)

    def moved(self, parameter: Parameter, shown) -> None:
        """A control moved to ``shown`` (log₁₀ of the value on a logarithmic slider)."""
        value = 10 ** float(shown) if parameter.log else shown
        try:
            value = parameter.parse(value)
        except ParameterError:
            self.refuse(parameter, entry.refusal(parameter, f"{value}", "is out of range",
                                                 self.state.values[parameter.name]))
            return
        if self.refused.pop(parameter.name, False) and np.isclose(value, self.state.values[parameter.name],
                                                                  rtol=1e-2):
            return                                # the box put back by refuse: its message stays
        entry.show(self.entries.get(parameter.name), value)
        self.tell(None, "")
        self.apply(parameter, value)
        self.follow_values(self.state.exercise)

    def refuse(self, parameter: Parameter, message: str) -> None:
        """A typed value that sets nothing (letters, empty, beyond the range) is refused, not clamped:
        one line names the parameter, the entry and the range, and the box and slider show the
        value in use again (issue 11, defect 10)."""
        in_use = self.state.values[parameter.name]
        self.tell(parameter.name, f"⚠️ {escaped(message)}")
        entry.show(self.entries.get(parameter.name), in_use)
        if not parameter.choices:
            self.put_slider(parameter, in_use)

    def follow(self, exercise: Exercise, values: dict) -> None:
        """Set ``values`` (name -> value) as if their controls had moved there; the controls show them."""
        for parameter in exercise.parameters:
            if parameter.name in values:
                value = values[parameter.name]
                self.moved(parameter, float(np.log10(value)) if parameter.log else value)
                self.put_slider(parameter, value)

    def put_slider(self, parameter: Parameter, value) -> None:
        """Move ``parameter``'s slider (if it has one) to ``value``; its echo changes nothing."""
        handle = self.inputs.get(parameter.name)
        shown = float(np.log10(value)) if parameter.log else value
        if handle is not None and handle is not self.entries.get(parameter.name) and handle.value != shown:
            self.refused[parameter.name] = True
            handle.value = shown
