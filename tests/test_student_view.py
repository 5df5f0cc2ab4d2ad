"""Issue 25, headless: what a student reads is where they look and agrees with itself (the
browser's side is in tests/test_browser_student_view.py)."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from markdown_it import MarkdownIt

from app.panels import page, readouts, worksheets
from app.panels.scope_charts import finite_extremes, on_page
from app.panels.scope_charts import page as scope_page
from app.panels.status import stopped
from app.panels.text import readout_rows
from lab_modules import recordings
from lab_modules.claims import markdown_table, settings_text
from lab_modules.exercises import get, registry
from lab_modules.parameters import ParameterError

MARKDOWN = MarkdownIt("commonmark").enable("table")


# -- readouts: the key ones pinned, a long list grouped and folded ------------------------------------
def test_key_readouts_are_pinned_in_their_order_and_a_word_carries_no_unit():
    rows = [("a", 1.0, "A"), ("b", "touched down", "µm"), ("c (scope window)", 2.0, "V")]
    pinned = readouts.pinned_markdown(rows, ("c", "b", "missing"))
    assert pinned.splitlines() == ["| key readout | value | unit |", "|---|---:|---|",
                                   "| c (scope window) | 2 | V |", "| b | touched down |  |"]
    assert readouts.pinned_markdown(rows, ()) == ""


def test_a_unit_stays_on_one_line_beside_a_long_label():
    """ekf_parameters at 1024 and 1366 px: "N/µm" broke after its slash in the narrow unit column."""
    row = readouts.row_markdown("True k_x at the operating point", 0.8, "N/µm")
    unit = row.split("|")[3].strip()
    assert unit == "N/" + readouts.WORD_JOINER + "µm" and unit.replace(readouts.WORD_JOINER, "") == "N/µm"


def test_a_key_readout_not_computed_yet_shows_a_dash_and_says_when_it_comes():
    """A key readout of the Analysis tab is computed only while that tab is shown (issue 23): pinned
    above the scope it is a dash until then, with a note that says so."""
    pinned = readouts.pinned_markdown([("a", 1.0, "A")], ("Critical speed 1", "a"), absent="—")
    lines = pinned.splitlines()
    assert lines[2:4] == ["| Critical speed 1 | — |  |", "| a | 1 | A |"]
    assert lines[-1] == f"*—: {readouts.ABSENT_NOTE}*" and "Analysis tab" in readouts.ABSENT_NOTE
    assert "*—" not in readouts.pinned_markdown([("a", 1.0, "A")], ("a",), absent="—")   # no note when none is absent


def test_a_long_list_is_grouped_by_subject_and_folded_the_scope_window_open():
    rows = [(f"Loose {k}", float(k), "A") for k in range(4)] + [(f"PID: figure {k}", 1.0, "%") for k in range(9)] \
        + [(f"LQG: figure {k}", 1.0, "%") for k in range(9)] + [("Single: one", 1.0, "")] \
        + [("LQG: RMS, this run (scope window)", 1.0, "A"), ("PID: RMS, this run (scope window)", 1.0, "A")]
    text = readouts.grouped_markdown(rows, ["a note"])
    html = MARKDOWN.render(text)
    assert html.count("<details") == 3 and html.count("<details open>") == 1   # PID, LQG folded; scope window open
    assert "<b>PID</b> (9 readouts)" in text and "<b>This run (scope window)</b> (2 readouts)" in text
    loose = text.split("<details")[0]
    assert "Loose 0" in loose and "Single: one" in loose and "PID: figure" not in loose
    assert all(label in text for label, _, _ in rows) and "*a note*" in text
    short = readouts.grouped_markdown(rows[:6])
    assert "<details" not in short and short.count("| quantity | value | unit |") == 1


@functools.cache
def shown_rows(name: str) -> tuple:
    """The readouts a tab of exercise ``name`` shows at its defaults: its analysis's (every step)
    and its scope window's after 2 s of simulated time."""
    exercise = get(name)
    values = exercise.resolve()
    result = exercise.analyse(values)
    rows = [row for analysis in ([result] if hasattr(result, "readouts") else list(result))
            for row in analysis.readouts]
    simulation = exercise.simulation(values)
    trace = np.vstack([simulation.advance(max(1, round(0.05 / simulation.sample_time_s))) for _ in range(40)])
    window = {column: trace[:, 1 + i] for i, column in enumerate(simulation.columns)}
    return tuple(rows + readout_rows(None, exercise, window))


@pytest.mark.parametrize("name", list(registry()))
def test_every_key_readout_exists(name):
    """Each exercise's pinned readouts are among what its analysis and its scope window show."""
    exercise = get(name)
    labels = {label for label, _, _ in shown_rows(name)}
    missing = [key for key in exercise.key_readouts if key not in labels and key + readouts.LIVE_SUFFIX not in labels]
    assert exercise.key_readouts and not missing, missing


@pytest.mark.parametrize("name", list(registry()))
def test_every_list_under_the_charts_shows_at_most_a_short_table_unfolded(name):
    """A long list is grouped so that what is not folded away is no longer than a short list (the
    last analysis step's rows, as the tab shows them, with the scope window's)."""
    exercise = get(name)
    result = exercise.analyse(exercise.resolve())
    last = result if hasattr(result, "readouts") else list(result)[-1]
    live = [row for row in shown_rows(name) if row[0].endswith(readouts.LIVE_SUFFIX)]
    loose, groups = readouts.sections(list(last.readouts) + live)
    assert len(loose) <= readouts.LONG_LIST_ROWS, [label for label, _, _ in loose]
    assert all(len(members) >= 2 for members in groups.values())



# -- ekf_parameters: the convergence time, the k_i axis ------------------------------------------------
def test_ekf_parameters_reads_when_both_estimates_entered_the_band_and_stayed():
    from lab_modules.exercises.ekf_parameters import CONVERGED_PERCENT, CONVERGENCE_LABEL, operating_point
    exercise = get("ekf_parameters")
    values = exercise.resolve()
    simulation = exercise.simulation(values)
    trace = np.vstack([simulation.advance(500) for _ in range(40)])     # 1 s in 40 frames
    columns = {name: trace[:, 1 + i] for i, name in enumerate(simulation.columns)}
    kx, ki = operating_point(0.0)
    inside = (np.abs(columns["ki_estimated_n_per_a"] / ki - 1) * 100 <= CONVERGED_PERCENT) \
        & (np.abs(columns["kx_estimated_n_per_m"] / kx - 1) * 100 <= CONVERGED_PERCENT)
    assert inside[-1] and not inside[0]
    entered = trace[np.flatnonzero(~inside)[-1] + 1, 0]                # after the last sample outside
    since = columns["within_band_since_s"]
    assert since[-1] == entered and 0.05 < entered < 0.5
    assert np.isnan(since[~inside]).all() and np.isfinite(since[inside]).all()
    shown = {label: value for label, value, _ in exercise.live_readouts(columns)}
    assert shown[CONVERGENCE_LABEL] == entered
    kept = exercise.retune(simulation, {**values, "prbs_amplitude_um": 6.0})     # same operating point: kept
    assert kept.entered_s == entered and kept.advance(10)[0, -1] == entered
    moved = exercise.retune(kept, {**values, "reference_offset_um": 100.0})       # another one: watched anew
    assert np.isnan(moved.entered_s)
    outside = exercise.live_readouts({**columns, "within_band_since_s": np.full(len(trace), np.nan)})
    assert CONVERGENCE_LABEL not in [label for label, _, _ in outside]        # no number while outside
    assert simulation.P.shape == (5, 5)                                       # the loop's own state, as before


def test_a_chart_whose_band_is_out_of_its_range_cuts_the_band():
    """The k_i chart's range follows the estimate, not the filter's starting ±3σ band (±90 %)."""
    chart = get("ekf_parameters").charts[0]
    assert chart.title.startswith("Force-current factor") and not chart.band_in_range
    assert all(c.band_in_range for c in get("kalman_noise").charts)
    assert finite_extremes(np.array([[1.0, np.nan], [-2.0, 5.0]], dtype=np.float32)) == (-2.0, 5.0)
    assert finite_extremes(np.full((2, 3), np.nan)) == (np.inf, -np.inf)


def test_the_time_since_reset_axis_pages_by_window_and_holds_its_extent():
    t = np.arange(20_000, 41_000) * 5e-5                          # 1.0 … 2.05 s
    buffer = np.column_stack([t, np.sin(t)])
    rows, frame_ms, start = scope_page(buffer, 1000.0)              # pages of 1 s: the page from 2 s
    assert start == 2.0 and rows[0, 0] == pytest.approx(2.0) and frame_ms == pytest.approx(49.95)
    t_ms = np.array([-frame_ms, -10.0, 0.0])
    x, ys = on_page(t_ms, np.ones((2, 3), dtype=np.float32), frame_ms, start, 1000.0)
    assert x[0] == 2.0 and x[-2] == pytest.approx(2.04995) and x[-1] == 3.0   # the page's whole extent
    assert np.isnan(ys[:, -1]).all() and ys.dtype == np.float32


# -- maglev_tuning: the preset's Q22 in the box, a restarted replay ------------------------------------
def test_the_nis_tuned_preset_shows_its_q22_and_only_that_preset_does():
    from lab_modules.exercises.maglev_tuning import filter_q
    exercise = get("maglev_tuning")
    tuned = exercise.resolve({"q_preset": "nis_tuned"})
    shown = exercise.following_values(tuned)
    assert shown == {"q_velocity": pytest.approx(filter_q(tuned)[1, 1])} and 1e-5 < shown["q_velocity"] < 1e-3
    assert exercise.following_values(exercise.resolve({"q_preset": "custom"})) == {}


def test_exercises_that_replay_afresh_on_every_change_say_so():
    restarting = {name for name, exercise in registry().items() if exercise.restarts_on_change}
    assert "maglev_tuning" in restarting and "kalman_noise" not in restarting and "ekf_parameters" not in restarting


def test_a_semicolon_recording_is_refused_naming_its_separator():
    content = b"time_s;reference_mm;measured_position_mm;coil_voltage_v\n0,000;14,8;14,80213;22,354\n"
    with pytest.raises(ParameterError, match=r"separated by semicolons \(';'.*'\.' as the decimal sign"):
        recordings.parse("sheet.csv", content)
    with pytest.raises(ParameterError, match="missing column"):
        recordings.parse("other.csv", b"time,position\n0,1\n")


# -- smaller items -----------------------------------------------------------------------------------
def test_a_stop_message_is_not_prefixed_twice():
    assert stopped("Stopped at t = 12.0 ms: the rotor touched down.").startswith(
        "**Stopped: at t = 12.0 ms, the rotor touched down.**")
    assert stopped("Stopped: the ball fell.").startswith("**Stopped: the ball fell.**")
    assert stopped("Touchdown").startswith("**Stopped: Touchdown**")


def test_the_browser_tab_is_named_after_the_lab_and_the_exercise():
    assert page.title_markdown("EKF estimating k_i & k_x") == \
        "<title>AMB estimation lab — EKF estimating k_i &amp; k_x</title>"


def test_claim_settings_and_other_exercises_are_named_as_the_student_sees_them():
    exercise = get("self_sensing")
    assert settings_text({"sigma_current_ma": 0.0, "unknown": 3}, exercise.parameters) == \
        "Current noise σ(i) = 0 mA, unknown = 3"
    table = markdown_table(exercise.claims, None, exercise.parameters)
    assert "sigma\\_current\\_ma" not in table and "Current noise σ(i) = 0 mA" in table
    sheet = worksheets.text(get("adaptive_filter"))
    assert "`stiffness_map`" not in sheet and f"*{get('stiffness_map').title}*" in sheet


def test_analysis_plots_hold_their_x_range_above_zero_on_a_log_axis():
    """lqg_vs_pid's fronts went from a two-point placeholder to 159 designs: viser carried the x range
    over in proportion, below zero on the log axis, and uPlot looped for its ticks ("Invalid array
    length"). Every plot now holds its own x range: its data, in whole decades on a log axis."""
    from app.panels.plots import plot_chart, x_range
    assert x_range(np.array([0.0233, 0.5, 7.43]), True) == (0.01, 10.0)
    assert x_range(np.array([0.159, 9990.0]), True) == (0.1, 10_000.0)
    assert x_range(np.array([-5.0, np.nan, 149.8]), False) == (-5.0, 149.8)
    assert x_range(np.array([np.nan, np.nan]), True) == (0.1, 1.0) and x_range(np.array([2.0]), False) == (1.5, 2.5)
    from lab_modules.exercises._lqg_vs_pid_fronts import front_plots
    values = get("lqg_vs_pid").resolve()
    for plot in front_plots(values, None):                        # the placeholder the first result shows
        _, options = plot_chart(plot)
        low, high = options["scales"]["x"]["range"]
        assert 0 < low < high and plot.log_x


def test_the_3d_view_folds_away_only_when_its_width_changes_sides():
    from app.panels.scene_view import SceneView

    class Scene:
        def __init__(self):
            self.sent = []

        def set_global_visibility(self, visible):
            self.sent.append(visible)
    view, scene = SceneView(), Scene()
    view.fit(scene, 386, 740)                      # 1366 x 768: room
    view.fit(scene, 120, 740)                      # 1024 x 768: viser's 120 px strip
    view.fit(scene, 118, 740)                      # a camera drag: nothing new to say
    view.fit(scene, 0, 0, attached=True)           # a new exercise's scene starts visible: hide it
    view.fit(scene, 920, 1050)                     # 1920 x 1080
    assert scene.sent == [False, False, True] and not view.hidden and view.due(10.0, 0.0)
    view.fit(scene, 120, 740)
    assert view.hidden and not view.due(10.0, 0.0)  # no animation while hidden


def test_an_export_names_the_file_it_sent_under_its_buttons():
    from types import SimpleNamespace

    from app.panels.export import ExportButtons
    sent = []
    exercise = get("kalman_noise")
    buttons = ExportButtons(exercise, lambda: (np.zeros((3, 1 + 1)), exercise.resolve(), ("x_true_m",), "KN-7Q3M"),
                            lambda: [("RMS displacement", 0.47, "µm")], lambda *args, **_: sent.append(args))
    buttons.note = SimpleNamespace(content="")
    buttons.send_readouts()
    name, content = sent[0]
    assert buttons.note.content.startswith("✓ Sent kalman") and "readouts" in name and \
        f"({len(content) / 1e3:.0f} kB)" in buttons.note.content
