"""The filter debugger: while paused, the filter's kept history (``lab_modules.estimators.filter_history``)
sample by sample: step back and forward or jump with the scrubber, the sample's predict and update
typeset with its numbers, the 1σ/2σ/3σ ellipses of P⁻ and P⁺ for two states around the estimates
and the true state, NEES/NIS over a chosen window with 95 % χ² bounds, and a branch (the filter
rerun from the shown sample with Q or R scaled, on the same measurements).

Shown for every simulation that offers ``filter_tape()`` (see ``exercises.Simulation``); nothing
is computed while the simulation runs."""

from __future__ import annotations

import itertools
import math

import numpy as np
import viser

from app.panels import filter_branch, scope
from app.panels.covariance_view import CovarianceView
from app.panels.inspector import prefixed, symbol
from app.panels.typeset import typeset
from lab_modules.estimators.filter_consistency import consistency
from lab_modules.estimators.filter_history import FilterHistory, branch
from lab_modules.formatting import number

RUNNING_NOTE = "*Pause the simulation to step back through the filter's last samples.*"
SIGMAS = (1, 2, 3)
PRIOR_COLOUR, POSTERIOR_COLOUR, TRUTH_COLOUR, MEASUREMENT_COLOUR = "#1f77b4", "#d62728", "#2ca02c", "#7f7f7f"
THE_RIG = "the rig"
GRID = 121                        # x points per ellipse half
DIGITS = 4


def available(simulation) -> bool:
    """A simulation with a sampled filter (``filter_tape()`` None: its filter corrects continuously)."""
    return callable(getattr(simulation, "filter_tape", None)) and simulation.filter_tape() is not None


def latex_number(value: float) -> str:
    """``value`` in LaTeX, 4 significant digits, powers of ten as ×10ⁿ."""
    if not math.isfinite(value):
        return r"\text{n/a}"
    exponent = 0 if value == 0 else math.floor(math.log10(abs(value)))
    if -2 <= exponent <= 3:
        return number(value, DIGITS).replace("−", "-")
    return rf"{number(value / 10**exponent, DIGITS).replace('−', '-')}\times 10^{{{exponent}}}"


def column(values) -> str:
    return r"\begin{bmatrix}" + r"\\".join(latex_number(v) for v in np.ravel(values)) + r"\end{bmatrix}"


def matrix(values) -> str:
    rows = np.atleast_2d(values)
    return r"\begin{bmatrix}" + r"\\".join("&".join(latex_number(v) for v in row) for row in rows) + r"\end{bmatrix}"


def equations(history: FilterHistory, row: int) -> str:
    """The sample's prediction and correction (eq. 2) with its numbers, in SI units."""
    s = history.sample(row)
    sigma_prior, sigma_post = np.sqrt(np.diag(s["P_prior"])), np.sqrt(np.diag(s["P_post"]))
    units = ", ".join(unit for _, unit in history.model.states)
    x_prediction, P_prediction = history.model.prediction
    return typeset("\n\n".join([
        f"**Sample {s['sample']}**, t = {s['time_s'] * 1e3:.3f} ms (states in {units}):",
        rf"$$\hat{{x}}^- = {x_prediction} = " + column(s["x_prior"]) + "$$",
        rf"$$P^- = {P_prediction},\quad \sigma^- = \sqrt{{\mathrm{{diag}}(P^-)}} = " + column(sigma_prior) + "$$",
        r"$$S = H P^- H^T + R = " + matrix(s["S"]) + "$$",
        r"$$K = P^- H^T S^{-1} = " + matrix(s["K"]) + "$$",
        r"$$\nu = y - H\hat{x}^- = " + column(s["y"]) + " - " + column(history.model.H @ s["x_prior"])
        + " = " + column(s["innovation"]) + "$$",
        r"$$\hat{x}^+ = \hat{x}^- + K\nu = " + column(s["x_post"]) + r",\quad \sigma^+ = " + column(sigma_post)
        + "$$",
        r"$$\text{true } x = " + column(s["truth"]) + "$$"]))


def ellipse(centre, P2, sigmas: float, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Upper and lower halves of (z − c)ᵀ P⁻¹ (z − c) = sigmas² over ``x`` (NaN outside)."""
    a, b, c = P2[0, 0], P2[0, 1], P2[1, 1]
    with np.errstate(invalid="ignore", divide="ignore"):
        dx = x - centre[0]
        # z = (dx, dy): c dx² − 2 b dx dy + a dy² = sigmas² (a c − b²), solved for dy
        root = np.sqrt((b * b - a * c) * dx * dx + a * sigmas**2 * (a * c - b * b))
        return centre[1] + (b * dx + root) / a, centre[1] + (b * dx - root) / a


def ellipse_series() -> tuple:
    """The ellipse chart's series (fixed, so that a new sample changes only the data): x, the
    upper and lower halves of the 1σ/2σ/3σ ellipses of P⁻ and P⁺, x̂⁻, x̂⁺, the true state and
    the measurement's constraint line."""
    series = [viser.uplot.Series(label="x")]
    for name, colour in (("P⁻", PRIOR_COLOUR), ("P⁺", POSTERIOR_COLOUR)):
        for sigmas in SIGMAS:
            dashed = {"dash": (4.0, 4.0)} if sigmas > 1 else {}
            series += [viser.uplot.Series(label=f"{sigmas}σ {name}{half}", stroke=colour, width=2.0 if sigmas == 1
                                          else 1.25, **dashed, points=viser.uplot.Series_Points(show=False))
                       for half in ("", " ")]
    series += [viser.uplot.Series(label=label, stroke=colour, width=0, points=viser.uplot.Series_Points(
        show=True, size=9, fill=colour, stroke=colour))
        for label, colour in (("x̂⁻", PRIOR_COLOUR), ("x̂⁺", POSTERIOR_COLOUR), ("true x", TRUTH_COLOUR))]
    series.append(viser.uplot.Series(label="H x = y", stroke=MEASUREMENT_COLOUR, width=1.5, dash=(8.0, 3.0),
                                     points=viser.uplot.Series_Points(show=False)))
    return tuple(series)


def constraint_line(history: FilterHistory, row: int, pair: tuple[int, int], x: np.ndarray) -> np.ndarray | None:
    """For a scalar measurement, the states of ``pair`` that explain y exactly with the others at
    x̂⁻: h_i x_i + h_j x_j = y − Σ_other h_k x̂⁻_k, as values over ``x`` (None: a vertical line at
    the returned x_i is drawn by the caller; NaN: no line, the measurement sees neither state)."""
    H, s = history.model.H, history.sample(row)
    if H.shape[0] != 1:
        return np.full(len(x), np.nan)
    i, j = pair
    rest = float(s["y"][0] - H[0] @ s["x_prior"] + H[0, i] * s["x_prior"][i] + H[0, j] * s["x_prior"][j])
    if H[0, j] != 0.0:
        return (rest - H[0, i] * x) / H[0, j]                  # x_j = (y' − h_i x_i) / h_j
    return None if H[0, i] != 0.0 else np.full(len(x), np.nan)


def ellipse_chart(history: FilterHistory, row: int, pair: tuple[int, int]) -> tuple[tuple, dict]:
    """uPlot data and options (``ellipse_series``): the ellipses of P⁻ (blue) and P⁺ (red) for
    states ``pair``, x̂⁻, x̂⁺ and the true state as points, a scalar measurement's constraint line."""
    i, j = pair
    s = history.sample(row)
    cut = np.ix_(pair, pair)
    prior, post = s["x_prior"][list(pair)], s["x_post"][list(pair)]
    truth = s["truth"][list(pair)]
    half = 3.05 * max(math.sqrt(s["P_prior"][i, i]), math.sqrt(s["P_post"][i, i]))
    points = [p for p in (prior[0], post[0], truth[0]) if math.isfinite(p)]
    x = np.unique(np.concatenate([np.linspace(min(points) - half, max(points) + half, GRID), points]))
    line = constraint_line(history, row, pair, x)
    vertical_at = None
    if line is None:                                          # h_j = 0: x_i = y' / h_i, its x twice
        H = history.model.H[0]
        vertical_at = float(s["y"][0] - H @ s["x_prior"] + H[i] * s["x_prior"][i]) / H[i]
        x = np.sort(np.concatenate([x, [vertical_at, vertical_at]]))
        line = np.full(len(x), np.nan)
    data = [x]
    for centre, P in ((prior, s["P_prior"][cut]), (post, s["P_post"][cut])):
        for sigmas in SIGMAS:
            data += list(ellipse(centre, P, sigmas, x))
    data += [np.where(x == point[0], point[1], np.nan) for point in (prior, post, truth)]
    (x_label, x_unit), (y_label, y_unit) = history.model.states[i], history.model.states[j]
    # SI values of µm or mA would all read 0 on uPlot's ticks: each axis in a prefixed unit
    x_factor, x_unit = prefixed(half / 3.0, x_unit)
    y_factor, y_unit = prefixed(3.0 * math.sqrt(s["P_prior"][j, j]), y_unit)
    data = [data[0] / x_factor] + [d / y_factor for d in data[1:]]
    finite = np.concatenate([d[np.isfinite(d)] for d in data[1:]])
    low, high = float(finite.min()), float(finite.max())
    margin = 0.05 * (high - low) or abs(high) or 1.0
    if vertical_at is not None:
        first = int(np.searchsorted(x, vertical_at))
        line[first], line[first + 1] = low - margin, high + margin            # the line spans the chart
    else:
        line = np.where((line / y_factor > low - margin) & (line / y_factor < high + margin), line / y_factor, np.nan)
    data.append(line)
    return tuple(data), {
        "title": f"P⁻ and P⁺ at sample {s['sample']}: 1σ, 2σ, 3σ",
        "axes": (viser.uplot.Axis(label=f"{x_label} [{x_unit}]"),
                 viser.uplot.Axis(label=f"{y_label} [{y_unit}]", size=70)),
        "scales": {"x": viser.uplot.Scale(time=False),
                   "y": viser.uplot.Scale(auto=False, min=low - margin, max=high + margin)}}


def consistency_text(history: FilterHistory, row: int, window: int) -> str:
    """NEES and NIS over the ``window`` samples up to the shown one, naming a filter outside its bounds."""
    shown = history.rows(max(0, row + 1 - window), row + 1)
    lines = [f"Consistency over the {len(shown)} samples up to {history.first_sample + row} (95 % χ² bounds):", "",
             "| test | mean | bounds | independent samples | verdict |", "|---|---:|---:|---:|---|"]
    for test in consistency(shown):
        verdict = "inside" if test.inside else f"**outside: {history.model.title} is {test.verdict}**"
        lines.append(f"| {test.name} ({test.dof} dof) | {number(test.mean, 3)} | {number(test.lower, 3)} … "
                     f"{number(test.upper, 3)} | {test.independent_samples} | {verdict} |")
    return "\n".join(lines)


class FilterDebugger:
    """The "Filter debugger" folder: scrubber, step buttons, equations, ellipses, consistency, branch."""

    def __init__(self, gui, states: tuple[tuple[str, str], ...], on, keep=None, scene=None, rig=None):
        """``on(name, function)`` makes a GUI callback of ``function`` (the tab's worker runs it);
        ``keep(q_scale, r_scale, model)`` makes a branch's Q and R the running setting and says what
        it did (None: branches cannot be kept); ``scene`` (the tab's viser SceneApi) shows the
        ellipsoids of three states in place of the exercise's ``rig`` (its attached ``SceneView``)."""
        self.history: FilterHistory | None = None
        self.rerun: FilterHistory | None = None   # the branch on show, if any
        self.keep = keep
        self.tape_key = None
        with gui.add_folder("Filter debugger", expand_by_default=False):
            self.note = gui.add_markdown(RUNNING_NOTE)
            self.scrubber = gui.add_slider("Sample", min=0, max=1, step=1, initial_value=0, disabled=True,
                                           hint="The kept samples of the filter (newest on the right).")
            self.steps = gui.add_button_group("Step", ("◀ 10", "◀ 1", "1 ▶", "10 ▶"))
            pairs = [f"{a[0]} / {b[0]}" for n, a in enumerate(states) for b in states[n + 1:]]
            self.pairs = [(n, m) for n in range(len(states)) for m in range(n + 1, len(states))]
            self.pair = gui.add_dropdown("Ellipse states", tuple(pairs), initial_value=pairs[0])
            self.triples = list(itertools.combinations(range(len(states)), 3))
            self.covariance = None if scene is None or not self.triples else CovarianceView(scene, rig, states)
            self.view_3d = None if self.covariance is None else gui.add_dropdown(
                "Ellipsoids in 3D", (THE_RIG, *(" / ".join(symbol(states[k][0]) for k in t) for t in self.triples)),
                initial_value=THE_RIG, hint="While paused: the 3σ ellipsoids of P⁻ and P⁺ for three states around "
                                            "the true state, in place of the rig.")
            self.window = gui.add_slider("NEES/NIS window", min=50, max=4000, step=50, initial_value=1000,
                                         hint="Samples up to the shown one that the consistency tests average.")
            self.chart = gui.add_uplot(scope.placeholder(0.0, 1.0, len(ellipse_series()) - 1), ellipse_series(),
                                       legend=viser.uplot.Legend(show=False), padding=scope.PADDING, aspect=1.2)
            self.readouts = gui.add_markdown("")
            self.q_scale = gui.add_number("Branch Q ×", initial_value=10.0, min=1e-6, max=1e6)
            self.r_scale = gui.add_number("Branch R ×", initial_value=1.0, min=1e-6, max=1e6)
            self.horizon = gui.add_slider("Branch horizon", min=50, max=4000, step=50,
                                          initial_value=filter_branch.AFTER, hint="Samples the branch reruns.")
            self.branch_button = gui.add_button("Branch from this sample",
                                                hint="Reruns the filter from here with Q and R scaled, on the same "
                                                     "measurements and inputs (the plant stays as recorded).")
            self.keep_drop = gui.add_button_group("Branch", ("Keep", "Drop"))
            self.overlay = gui.add_uplot(scope.placeholder(0.0, 1.0, len(filter_branch.SERIES) - 1),
                                         filter_branch.SERIES, legend=viser.uplot.Legend(show=True),
                                         padding=scope.PADDING, aspect=1.6)
            self.branch_text = gui.add_markdown("")
            self.text = gui.add_markdown("")
        moves = {"◀ 10": -10, "◀ 1": -1, "1 ▶": 1, "10 ▶": 10}
        self.steps.on_click(on("debugger step", lambda: self.step(moves[self.steps.value])))
        for handle in (self.scrubber, self.pair, self.window, self.view_3d):
            if handle is not None:
                handle.on_update(on("debugger view", self.draw))
        self.branch_button.on_click(on("debugger branch", self.show_branch))
        self.keep_drop.on_click(on("debugger keep", lambda: self.keep_or_drop(self.keep_drop.value)))

    @classmethod
    def add(cls, gui, simulation, on, keep=None, scene=None, rig=None) -> FilterDebugger | None:
        """The debugger for ``simulation`` (None without a filter tape)."""
        return cls(gui, simulation.filter_tape().model.states, on, keep, scene, rig) if available(simulation) else None

    def show(self, running: bool, simulation) -> None:
        """Replay the tape when paused (newest sample shown); hide the views while running."""
        self.scrubber.disabled = running
        if running or not available(simulation):
            self.note.content, self.history = RUNNING_NOTE, None
            if self.covariance is not None:
                self.covariance.hide()                # the rig moves again
            return
        tape = simulation.filter_tape()
        key = (id(tape), tape.count, tape.chunks[-1][0] if tape.chunks else None)
        if key != self.tape_key:
            self.tape_key, self.history, self.rerun = key, tape.history(), None
        if self.history is None:
            self.note.content = "*No samples yet: press Run or Step.*"
            return
        first, last = self.history.first_sample, self.history.first_sample + len(self.history) - 1
        self.note.content = f"Samples {first} … {last} are kept: step back, or drag the scrubber."
        self.scrubber.min, self.scrubber.max = first, max(last, first + 1)
        self.scrubber.value = last
        self.draw()

    def step(self, samples: int) -> None:
        if self.history is not None:
            self.scrubber.value = int(np.clip(self.scrubber.value + samples, self.scrubber.min,
                                              self.history.first_sample + len(self.history) - 1))
            self.draw()

    def row(self) -> int:
        return int(np.clip(int(self.scrubber.value) - self.history.first_sample, 0, len(self.history) - 1))

    def draw(self) -> None:
        if self.history is None:
            return
        row = self.row()
        data, options = ellipse_chart(self.history, row, self.pairs[self.pair.options.index(self.pair.value)])
        self.chart.axes, self.chart.scales, self.chart.title = options["axes"], options["scales"], options["title"]
        self.chart.data = data
        self.text.content = equations(self.history, row)
        self.readouts.content = consistency_text(self.history, row, int(self.window.value))
        pair = self.pairs[self.pair.options.index(self.pair.value)]
        data, options = filter_branch.overlay_chart(self.history, row, pair[0], self.rerun, int(self.horizon.value))
        self.overlay.axes, self.overlay.scales, self.overlay.title = options["axes"], options["scales"], options["title"]
        self.overlay.data = data
        if self.view_3d is not None:
            if self.view_3d.value == THE_RIG:
                self.covariance.hide()
            else:
                triple = self.triples[self.view_3d.options.index(self.view_3d.value) - 1]
                self.covariance.show(self.history.sample(row), triple)

    def show_branch(self) -> None:
        if self.history is None:
            return
        row = self.row()
        model = self.history.model.scaled(float(self.q_scale.value), float(self.r_scale.value))
        rerun = self.rerun = branch(self.history, row, model, int(self.horizon.value))
        original = self.history.rows(row, row + len(rerun))
        lines = [(f"Branch from sample {self.history.first_sample + row} with Q ×{number(self.q_scale.value)}, "
                  f"R ×{number(self.r_scale.value)} over {len(rerun)} samples:"), "",
                 "| | NEES | NIS | RMS error of the first state |", "|---|---:|---:|---:|"]
        for name, part in (("original", original), ("branch", rerun)):
            tests = {test.name: test for test in consistency(part)}
            cells = [f"{number(t.mean, 3)} ({'in' if t.inside else 'out'})" if t else "n/a (no true state)"
                     for t in (tests.get("NEES"), tests["NIS"])]
            error = part.truth[:, 0] - part.x_post[:, 0]
            lines.append(f"| {name} | {cells[0]} | {cells[1]} "
                         f"| {number(float(np.sqrt(np.mean(error**2))))} {self.history.model.states[0][1]} |")
        self.branch_text.content = "\n".join(lines)
        self.draw()

    def keep_or_drop(self, which: str) -> None:
        """"Keep": the branch's Q and R become the running setting (the tab's controls follow);
        "Drop": the branch leaves the charts."""
        if which == "Keep" and self.rerun is not None and self.keep is not None:
            model, tuned = self.history.model, self.rerun.model
            self.branch_text.content = self.keep(tuned.q_scale / model.q_scale, float(tuned.R[0, 0] / model.R[0, 0]),
                                                 model)
            return
        self.rerun, self.branch_text.content = None, ""
        self.draw()
