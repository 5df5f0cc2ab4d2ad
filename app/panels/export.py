"""Export for a lab report: the scope window as CSV, each scope chart as PNG and the
readouts as CSV, from buttons under the Scope tab's readouts.

Everything is made on the server from the tab's scope buffer (the samples the
charts show, every sample, not the thinned points sent to the browser), so a
file holds exactly what the student saw and the tests can check it.  The PNGs
are drawn by matplotlib (``matplotlib.figure`` only, no pyplot, Agg canvas)
like the scope: the same series, colours, units and ±3σ band.  File names
carry the exercise, the tab's experiment code (``app/infra/store.py``) when it has
one, and the server's local time: ``kalman_noise_KN-7Q3M_20261123-141502_scope.csv``.
"""

from __future__ import annotations

import io
import re
import time
from collections.abc import Callable

import numpy as np
import viser
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from app.panels.text import escaped
from lab_modules.exercises import Chart, Exercise
from lab_modules.exercises._figures import draw_chart
from lab_modules.parameters import ParameterError

#: Unit tokens at the end of a column name (``x_true_m``, ``ki_true_n_per_a``) and their symbols
UNIT_TOKENS = {"m": "m", "mm": "mm", "s": "s", "a": "A", "v": "V", "n": "N", "h": "H"}
_UNIT = re.compile(r"_(m|mm|s|a|v|n|h)(?:_per_(m|mm|s|a|v|n|h))?$")
_LOOP_SUFFIX = re.compile(r"_(lqg|pid)$")          # lqg_vs_pid's side-by-side columns: x_true_m_lqg
PNG_DPI = 150
FIGURE_IN = (8.0, 3.6)                             # width, height [inch]


def column_unit(name: str, charts: tuple[Chart, ...] = ()) -> str:
    """The SI unit of a trace column, read from its name's suffix (``_m``, ``_n_per_a``,
    ``_m_per_s``); a column without one takes the unit of a chart that plots it unscaled,
    else it is a pure number ("1")."""
    match = _UNIT.search(_LOOP_SUFFIX.sub("", name))
    if match:
        numerator, denominator = match.groups()
        unit = UNIT_TOKENS[numerator]
        return f"{unit}/{UNIT_TOKENS[denominator]}" if denominator else unit
    for chart in charts:
        for series in chart.series:
            if series.column == name and series.scale == 1.0:
                return chart.unit
    return "1"


def _number(value: float | str) -> str:
    """Shortest text that reads back as the same float (``repr``); a word readout
    ("touched down", "computing …") as it is shown."""
    return _csv_field(value) if isinstance(value, str) else repr(float(value))


def _csv_field(text: str) -> str:
    text = str(text)
    return '"' + text.replace('"', '""') + '"' if any(c in text for c in ',"\n') else text


def _comments(exercise: Exercise, code: str | None, values: dict) -> list[str]:
    settings = "; ".join(f"{p.name} = {values[p.name]}{' ' + p.unit if p.unit else ''}"
                         for p in exercise.parameters if p.name in values)
    return [f"# exercise: {exercise.name} ({exercise.title})",
            f"# experiment code: {code or 'none (this server keeps no experiments)'}",
            f"# exported: {time.strftime('%Y-%m-%d %H:%M:%S %Z')}",
            f"# settings: {settings}"]


def filename(exercise: Exercise, code: str | None, what: str, extension: str,
             now: float | None = None) -> str:
    """``exercise_CODE_YYYYmmdd-HHMMSS_what.ext`` (no code part without a code)."""
    stamp = time.strftime("%Y%m%d-%H%M%S", time.localtime(now))
    what = re.sub(r"[^A-Za-z0-9]+", "-", what).strip("-").lower()
    return "_".join(part for part in (exercise.name, code, stamp, what) if part) + f".{extension}"


def scope_csv(exercise: Exercise, columns: tuple[str, ...], buffer: np.ndarray, values: dict,
              code: str | None = None) -> bytes:
    """The scope window: comment lines (exercise, code, time, settings), then a header
    ``time_s [s],x_true_m [m],...`` and one row per sample of ``buffer`` (time, *columns)."""
    header = ["time_s [s]"] + [f"{name} [{column_unit(name, exercise.charts)}]" for name in columns]
    lines = _comments(exercise, code, values) + [",".join(header)]
    lines += [",".join(_number(v) for v in row) for row in buffer]
    return ("\n".join(lines) + "\n").encode()


def readouts_csv(exercise: Exercise, rows: list[tuple[str, float, str]], values: dict,
                 code: str | None = None) -> bytes:
    """The readouts as ``quantity,value,unit`` rows (after the same comment lines)."""
    lines = _comments(exercise, code, values) + ["quantity,value,unit"]
    lines += [f"{_csv_field(label)},{_number(value)},{_csv_field(unit)}" for label, value, unit in rows]
    return ("\n".join(lines) + "\n").encode()


def chart_png(exercise: Exercise, chart: Chart, columns: tuple[str, ...], buffer: np.ndarray,
              code: str | None = None) -> bytes:
    """One scope chart over the scope window as a PNG, drawn like the scope."""
    figure = Figure(figsize=FIGURE_IN, layout="constrained")
    axes = figure.add_subplot()
    index = {name: 1 + i for i, name in enumerate(columns)}
    draw_chart(axes, chart, buffer, index)
    axes.set_title(f"{exercise.title}: {chart.title}" + (f" ({code})" if code else ""), fontsize="medium")
    axes.set(xlabel="time t [s]", ylabel=f"{chart.title} [{chart.unit}]" if len(chart.title) < 24
             else f"[{chart.unit}]")
    axes.legend(fontsize="x-small", loc="upper right")
    out = io.BytesIO()
    FigureCanvasAgg(figure)
    figure.savefig(out, format="png", dpi=PNG_DPI)
    return out.getvalue()


class ExportButtons:
    """The Scope tab's folder "Export for your report": CSV of the scope window and of the
    readouts, a PNG per chart."""

    def __init__(self, exercise: Exercise, snapshot: Callable[[], tuple],
                 readout_rows: Callable[[], list], send: Callable[..., None]):
        """``snapshot()`` gives (scope buffer, values, column names, experiment code);
        ``readout_rows()`` the readouts shown; ``send(filename, content, save_immediately=True)``
        sends a file to the browser."""
        self.exercise, self.snapshot, self.readout_rows, self.send = exercise, snapshot, readout_rows, send
        self.note = None                          # what the last button sent, under the buttons

    @classmethod
    def add(cls, gui, exercise: Exercise, on, snapshot, readout_rows, send) -> ExportButtons:
        """The buttons (call inside the Scope tab while the GUI is built)."""
        buttons = cls(exercise, snapshot, readout_rows, send)
        with gui.add_folder("Export for your report", expand_by_default=False):
            gui.add_markdown("*Files named after the exercise, the experiment code and the time. "
                             "The scope window holds every sample of the charts; pause first to keep "
                             "the CSV and the pictures of the same moment.*")
            choices = {"Scope window (CSV)": buttons.send_scope, "Readouts (CSV)": buttons.send_readouts}
            for chart in exercise.charts:
                choices[f"Chart: {chart.title} (PNG)"] = lambda chart=chart: buttons.send_chart(chart)
            for label, action in choices.items():
                button = gui.add_button(label, icon=viser.Icon.DOWNLOAD)
                button.on_click(on(("export", label), action))
            buttons.note = gui.add_markdown("")
        return buttons

    def _send(self, name: str, content) -> None:
        """Send a file; the note under the buttons names it (the student sees what a press did)."""
        self.send(name, content, save_immediately=True)
        if self.note is not None:
            self.note.content = f"✓ Sent {escaped(name)} ({len(content) / 1e3:.0f} kB)."

    def send_scope(self) -> None:
        buffer, values, columns, code = self.snapshot()
        self._send(filename(self.exercise, code, "scope", "csv"),
                   scope_csv(self.exercise, columns, buffer, values, code))

    def send_readouts(self) -> None:
        _, values, _, code = self.snapshot()
        self._send(filename(self.exercise, code, "readouts", "csv"),
                   readouts_csv(self.exercise, self.readout_rows(), values, code))

    def send_chart(self, chart: Chart) -> None:
        buffer, _, columns, code = self.snapshot()
        self._send(filename(self.exercise, code, chart.title, "png"),
                   chart_png(self.exercise, chart, columns, buffer, code))


def add_download(gui, exercise: Exercise, on, values_now: Callable[[], dict], client) -> None:
    """The exercise's own download button (``exercise.download_label``) with a note under it that
    says what a press did (issue 11, defect 5: the reason a recording failed used to appear below
    the fold of the left panel)."""
    button = gui.add_button(exercise.download_label, icon=viser.Icon.DOWNLOAD)
    note = gui.add_markdown("")

    def download() -> None:
        note.content = "*Preparing the file …*"
        client.flush()
        try:
            name, content = exercise.download(values_now())
        except ParameterError as error:
            note.content = f"⚠️ {escaped(error)}"
            return
        client.send_file_download(name, content, save_immediately=True)
        note.content = f"Sent {escaped(name)} ({len(content) / 1e3:.0f} kB)."
    button.on_click(on("download", download))
