"""The Pole map tab: one colour legend for the whole lab, labelled poles, root loci.

It draws what ``lab_modules.evaluation`` computes (``poles.view``: the pole sets with their
declared categories, numbered modes and names, and the root locus): two maps, the dominant
poles and all poles, each set in its category's colour (issue 11, defect 15; a second set
of one category hollow), the mode numbers on a top axis above each map, the table of the
modes below them, and the root locus as small dots in the closed-loop colour, the poles at
the current factor drawn large on them.  The "Show mode" dropdown (``mode_picker``) rings
one mode on both maps.
"""

from __future__ import annotations

import numpy as np
import viser

from app.panels import scope
from lab_modules.evaluation.poles import (
    CATEGORIES,
    Category,
    Mode,
    PoleView,
    dominant_decay_rad_s,
    duration_text,
)
from lab_modules.evaluation.root_locus import Locus
from lab_modules.formatting import number

LIGHT_DAMPING = 0.3               # poles below this damping always belong to the dominant view
LABEL_PX, CHAR_PX, LABEL_SPACE_PX = 470, 7, 6   # plot width, label character width, space between labels [px]
MARGIN = 0.08                     # share of the pole span added on each side of a map
LOCUS_COLOR = "#9ecae1"           # the closed-loop colour, light: the root locus
MARK_COLOR, MARK_SIZE = "#ff7f0e", 24.0    # the ring around the mode chosen in "Show mode"
#: Marker (size, hollow) of the 1st, 2nd, 3rd ... set of one category in a map
MARKERS = ((9.0, False), (10.0, True), (6.0, False), (13.0, True))


def legend_markdown() -> str:
    """The one colour legend of the lab (the same text in every exercise)."""
    dots = " &nbsp; ".join(f'<span style="color:{c.color}">●</span> {c.meaning}' for c in CATEGORIES)
    return (f"**Colours (every exercise):** {dots} &nbsp; <span style=\"color:{LOCUS_COLOR}\">•</span> "
            "root locus: the closed loop's poles as the gain factor sweeps its range. A hollow marker is a "
            "second set of the same kind. The numbers on the top axis are the modes of the table below.")


def pole_text(mode: Mode, digits: int = 3) -> str:
    """s of a mode as text: "-12.5" or "-3 ± 4j"."""
    real = number(mode.pole.real, digits)
    return real if mode.is_real else f"{real} ± {number(mode.pole.imag, digits)}j"


def table_markdown(pole_view: PoleView | dict) -> str:
    """The pole table: every mode with its number, set, name (or kind), f_n, ζ and s."""
    if isinstance(pole_view, dict):
        pole_view = PoleView(pole_view)
    rows = ["| # | set | mode | f_n [Hz] | ζ | s [rad/s] |", "|---:|---|---|---:|---:|---|"]
    for m in pole_view.modes():
        dot = f'<span style="color:{m.category.color}">●</span>'
        rows.append(f"| {m.number} | {dot} {m.set_name} | {m.label} | {number(m.natural_hz)} "
                    f"| {number(m.damping)} | {pole_text(m)} |")
    return "\n".join(rows)


# -- the two maps ---------------------------------------------------------------------------------
def _dominant(p: np.ndarray, limit: float) -> np.ndarray:
    p = np.asarray(p, dtype=complex)
    damping = -p.real / np.maximum(np.abs(p), 1e-300)
    return p[(np.abs(p.real) <= limit) | (damping < LIGHT_DAMPING)]


def charts(pole_view: PoleView | dict, marked: Mode | None = None) -> tuple[tuple[tuple, dict], tuple[tuple, dict]]:
    """uPlot arguments of the two pole maps: the dominant poles (slow, or lightly
    damped: |Re s| below ``dominant_decay_rad_s`` or damping below
    ``LIGHT_DAMPING``) and all poles; ``marked`` (the "Show mode" choice) ringed on both."""
    if isinstance(pole_view, dict):
        pole_view = PoleView(pole_view)
    poles, path = pole_view.poles, pole_view.locus
    limit = dominant_decay_rad_s(poles)
    numbered = pole_view.modes()
    categories = {name: pole_view.category(name) for name in poles}
    chosen = {name: _dominant(p, limit) for name, p in poles.items()}
    path_points = np.zeros(0, dtype=complex) if path is None else path.poles.ravel()
    path_points = path_points[np.isfinite(path_points)]
    title = f"Dominant poles (Re s > −{limit:.0f} rad/s or damping ζ < {LIGHT_DAMPING})"
    shown_modes = [m for m in numbered if _dominant(np.array([m.pole]), limit).size]
    in_dominant = marked if marked is not None and _dominant(np.array([marked.pole]), limit).size else None
    return (pole_map(chosen, categories, title, shown_modes, _dominant(path_points, limit), path, in_dominant),
            pole_map(poles, categories, "All poles", numbered, path_points, path, marked))


def span(points: np.ndarray) -> tuple[tuple[float, float], tuple[float, float]]:
    """(x range, y range) [rad/s] of a map: every point and the imaginary axis inside, with
    ``MARGIN`` of the span on each side; the y range symmetric (conjugate pairs)."""
    points = np.asarray(points, dtype=complex)
    real = np.append(points.real, 0.0)
    low, high = float(real.min()), float(real.max())
    width = high - low or max(abs(low), 1.0)
    reach = float(np.abs(points.imag).max()) if points.size else 0.0
    if reach == 0.0:                                  # all poles real: a square-ish view of the real axis
        reach = 0.5 * width
    return (low - MARGIN * width, high + MARGIN * width), (-(1 + MARGIN) * reach, (1 + MARGIN) * reach)


def _label_text(group: list[Mode]) -> str:
    numbers = sorted(m.number for m in group)
    return ",".join(map(str, numbers)) if len(numbers) <= 2 else f"{numbers[0]},{numbers[1]},+{len(numbers) - 2}"


def top_axis_labels(shown: list[Mode], x_range: tuple[float, float]) -> tuple[tuple[float, ...], tuple[str, ...]]:
    """Top-axis positions and texts of the mode numbers; labels that would overlap (at
    ``LABEL_PX`` of plot width) merge into one ("3,7" or "3,7,+2": two more)."""
    px_per_unit = LABEL_PX / (x_range[1] - x_range[0])

    def centre(group: list[Mode]) -> float:
        return float(np.mean([m.pole.real for m in group]))

    def overlap(a: list[Mode], b: list[Mode]) -> bool:
        room = (len(_label_text(a)) + len(_label_text(b))) * CHAR_PX / 2 + LABEL_SPACE_PX
        return (centre(b) - centre(a)) * px_per_unit < room

    groups = [[m] for m in sorted(shown, key=lambda m: m.pole.real)]
    merged = True
    while merged:
        merged = False
        for k in range(len(groups) - 1):
            if overlap(groups[k], groups[k + 1]):
                groups[k:k + 2] = [groups[k] + groups[k + 1]]
                merged = True
                break
    return tuple(centre(g) for g in groups), tuple(_label_text(g) for g in groups)


def pole_map(poles: dict[str, np.ndarray], categories: dict[str, Category], title: str, shown: list[Mode],
             path_points: np.ndarray | None = None, path: Locus | None = None,
             marked: Mode | None = None) -> tuple[tuple, dict]:
    """A pole map as a scatter plot over one shared, sorted real axis (each pole
    set a series in its category's colour, with gaps where the others have their
    poles), with the imaginary axis drawn as a dashed line between two extra rows
    at Re s = 0, the root locus (if any) as small dots under the poles, the numbers
    of the ``shown`` modes on the top axis, and explicit ranges that hold every
    point (issue 11, defect 3)."""
    path_points = np.zeros(0, dtype=complex) if path_points is None else np.asarray(path_points, dtype=complex)
    x_range, y_range = span(np.concatenate([np.asarray(p, dtype=complex) for p in poles.values()] + [path_points]))
    layers = []                                       # (series options, points), drawn in this order
    if path is not None:
        layers.append((viser.uplot.Series(
            label=path.label, stroke=LOCUS_COLOR, width=0,
            points=viser.uplot.Series_Points(show=True, size=4.0, width=0, fill=LOCUS_COLOR, stroke=LOCUS_COLOR)),
            path_points))
    counts: dict[str, int] = {}
    for name, points in poles.items():
        color = categories[name].color
        size, hollow = MARKERS[min(counts.get(color, 0), len(MARKERS) - 1)]
        counts[color] = counts.get(color, 0) + 1
        layers.append((viser.uplot.Series(
            label=name, stroke=color, width=0,
            points=viser.uplot.Series_Points(show=True, size=size, width=2.0,
                                             fill="#ffffff" if hollow else color, stroke=color)),
            np.asarray(points, dtype=complex)))
    if marked is not None:                            # a ring around the chosen mode (and its mirror)
        ring = np.array([marked.pole] if marked.is_real else [marked.pole, np.conj(marked.pole)])
        layers.append((viser.uplot.Series(
            label=f"mode #{marked.number}: {marked.label}", stroke=MARK_COLOR, width=0,
            points=viser.uplot.Series_Points(show=True, size=MARK_SIZE, width=3.0, fill="rgba(0,0,0,0)",
                                             stroke=MARK_COLOR)), ring))
    axis_ends = np.array([y_range[0], y_range[1]]) / (1 + MARGIN) * 1j
    layers.append((viser.uplot.Series(label="Re s = 0", stroke="#000000", width=1, dash=(6.0, 4.0),
                                      points=viser.uplot.Series_Points(show=False)), axis_ends))
    rows = sorted((p.real, p.imag, k) for k, (_, points) in enumerate(layers) for p in points)
    x = np.array([r[0] for r in rows])
    columns = [np.full(len(x), np.nan) for _ in layers]
    for row, (_, value, k) in enumerate(rows):
        columns[k][row] = value
    splits, texts = top_axis_labels(shown, x_range)
    axes = (viser.uplot.Axis(label="Re s [rad/s]"), viser.uplot.Axis(label="Im s [rad/s]", size=scope.Y_AXIS_SIZE),
            viser.uplot.Axis(side=0, scale="x", label="mode # (table below)", labelSize=16, size=20,
                             splits=splits, values=texts, grid={"show": False}, ticks={"show": True, "size": 4}))
    return (x, *columns), {
        "series": (viser.uplot.Series(label="Re s [rad/s]"), *(options for options, _ in layers)),
        "title": title, "legend": viser.uplot.Legend(live=False), "padding": scope.PADDING, "axes": axes,
        "scales": {"x": viser.uplot.Scale(time=False, range=x_range),
                   "y": viser.uplot.Scale(auto=False, min=y_range[0], max=y_range[1])}}


# -- "Show mode": one mode ringed on the maps, with its name and state participation ------------
NO_MODE = "(none)"
DETAIL_DIGITS = 4                 # s and f_n of the chosen mode: one digit more than the table


def mode_choice(mode: Mode) -> str:
    """The "Show mode" dropdown's text of a mode."""
    return f"#{mode.number} {mode.label} ({number(mode.natural_hz)} Hz)"


def mode_choices(pole_view: PoleView) -> tuple[str, ...]:
    return (NO_MODE, *(mode_choice(m) for m in pole_view.modes()))


def follow(pole_view: PoleView, previous: Mode | None) -> Mode | None:
    """The mode of ``pole_view`` that is ``previous`` after a slider moved: the same set and
    name (the nearest pole if several share it), else the same number; None if none is left."""
    if previous is None:
        return None
    found = pole_view.modes()
    alike = [m for m in found if m.set_name == previous.set_name and m.label == previous.label]
    if alike:
        return min(alike, key=lambda m: abs(m.pole - previous.pole))
    return next((m for m in found if m.number == previous.number and m.set_name == previous.set_name), None)


def chosen(pole_view: PoleView, choice: str) -> Mode | None:
    return next((m for m in pole_view.modes() if mode_choice(m) == choice), None)


def detail_markdown(mode: Mode | None) -> str:
    """What the student reads about the chosen mode: name, set, s, f_n, ζ, time constant and the
    states that take part in it (participation factors, ``analysis.participation``)."""
    if mode is None:
        return ("*Pick a mode in “Show mode” to ring it on both maps (orange) and read its name, "
                "frequency, damping and which states take part in it.*")
    decay = duration_text(-1.0 / mode.pole.real) if mode.pole.real < 0 else "— (not decaying)"
    lines = [(f"**Mode #{mode.number}: {mode.label}** "
             f'(<span style="color:{mode.category.color}">●</span> {mode.set_name})'), "",
             "| s [rad/s] | f_n [Hz] | ζ | time constant τ = −1/Re s |", "|---|---:|---:|---:|",
             (f"| {pole_text(mode, DETAIL_DIGITS)} | {number(mode.natural_hz, DETAIL_DIGITS)} "
              f"| {number(mode.damping)} | {decay} |")]
    shown = [(label, share) for label, share in mode.shares if share >= 0.01]
    if shown:
        lines += ["", "State participation (share of the mode; the name is the physics with the largest share):", "",
                  "| state [unit] | share |", "|---|---:|"]
        lines += [f"| {label} | {100 * share:.0f} % |" for label, share in shown]
    else:
        lines += ["", "*(named from the plant model's structure; no participation factors for this set)*"
                  if mode.name else "*(no state matrix for this set: generic kind only)*"]
    return "\n".join(lines)
