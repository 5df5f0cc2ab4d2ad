"""Analyses on demand (issue 23): each panel's part of an exercise's analysis, results remembered
per setting of the parameters they read, the closed forms that replaced bisections, and a tab that
computes a panel only while the browser shows it (headless clients report it like the browser's
beacon)."""

from __future__ import annotations

import asyncio
import importlib

import numpy as np
import pytest

from lab_modules import analysis
from lab_modules.exercises import (
    ANALYSIS,
    PANELS,
    POLE_MAP,
    SCOPE,
    Analysis,
    get,
    kalman_noise,
    results,
    sensor_placement,
)
from lab_modules.memo import Memo, ReadValues, remembered
from lab_modules.parameters import in_si
from tests.example_exercise import contract_exercises
from tests.wsclient import RawTab, lab_process, run_async

EXERCISES = contract_exercises()
SPLIT = ("kalman_noise", "stiffness_map", "adaptive_filter", "thrust_liftoff", "lqg_vs_pid", "rotor_at_speed",
         "ekf_disturbance", "self_sensing")


def _last(result) -> Analysis:
    return list(results(result))[-1]


# -- the contract: each panel's part, and analyse as all of them ------------------------------------
@pytest.mark.parametrize("name", sorted(EXERCISES))
def test_each_panel_has_its_part_and_analyse_is_all_of_them(name):
    exercise = EXERCISES[name]
    values = exercise.resolve({})
    parts = {panel: exercise.analyse_panel(dict(values), panel) for panel in PANELS}
    assert parts[SCOPE] is not None
    last = {panel: _last(part) for panel, part in parts.items() if part is not None}
    whole = _last(exercise.analyse(dict(values)))
    scope = last[SCOPE]
    tab = last.get(ANALYSIS)
    assert [r[0] for r in whole.readouts] == [r[0] for r in scope.readouts + (tab.readouts if tab else [])]
    assert whole.poles.keys() == last.get(POLE_MAP, scope).poles.keys()
    assert [p.title for p in whole.plots] == [p.title for p in scope.plots + (tab.plots if tab else [])]


@pytest.mark.parametrize("name", SPLIT)
def test_split_exercises_keep_the_scope_quick_and_free_of_plots(name):
    """The costly exercises compute their plots and slow figures for the Analysis tab only."""
    exercise = get(name)
    scope = list(results(exercise.analyse_panel(exercise.resolve({}), SCOPE)))
    assert len(scope) == 1 and scope[0].readouts and not scope[0].plots and not scope[0].poles
    assert exercise.analyse_panel(exercise.resolve({}), ANALYSIS) is not None


# -- pay once ----------------------------------------------------------------------------------------
def test_read_values_note_what_is_read():
    values = ReadValues({"a": 1, "b": 2, "c": 3})
    assert values["a"] == 1 and values.get("b") == 2 and "z" not in values
    assert values.read == {"a", "b", "z"}
    copied = ReadValues({"a": 1, "b": 2})
    assert dict(copied) == {"a": 1, "b": 2} and copied.read == {"a", "b"}   # a copy reads everything
    compared = ReadValues({"a": 1})
    assert compared == {"a": 1} and compared.read == {"a"}


def test_memo_computes_once_per_setting_of_what_was_read():
    calls = []

    @remembered(size=3)
    def twice_a(values):
        calls.append(1)
        return 2 * values["a"] + (values["b"] if values["a"] > 0 else 0)

    assert twice_a({"a": 1, "b": 5, "c": 0}) == 7
    assert twice_a({"a": 1, "b": 5, "c": 9}) == 7 and len(calls) == 1      # c is never read
    assert twice_a({"a": -1, "b": 5}) == -2 and len(calls) == 2
    assert twice_a({"a": -1, "b": 8}) == -2 and len(calls) == 2            # this branch never reads b
    assert twice_a({"a": 1, "b": 6}) == 8 and len(calls) == 3
    for a in range(2, 6):                                                  # bounded: the oldest go
        twice_a({"a": a, "b": 0})
    assert len(twice_a.memo.entries) == 3
    twice_a({"a": 1, "b": 5})
    assert len(calls) == 8


def test_nested_memos_mark_what_the_inner_one_read():
    @remembered()
    def inner(values):
        return values["a"]

    outer = Memo()
    read = []

    def compute(values):
        result = inner(values) + 1
        read.append(set(values.read))
        return result
    assert outer.call("k", {"a": 1, "b": 2}, compute) == 2
    assert outer.call("k", {"a": 1, "b": 3}, compute) == 2 and len(read) == 1 and read[0] == {"a"}
    assert inner({"a": 1, "b": 4}) == 1                                    # now remembered: marks it too
    assert outer.call("k", {"a": 2, "b": 3}, compute) == 3 and read[-1] == {"a"}


def test_si_values_read_a_control_only_when_it_is_asked_for():
    """A computation that converts through ``in_si`` depends on the controls it converts, not on
    every numeric control of its exercise."""
    exercise = get("kalman_noise")
    read = ReadValues(exercise.resolve({}))
    si = in_si(kalman_noise.PARAMETERS, read)
    assert not read.read
    assert si["sensor_lag_us"] == read.raw()["sensor_lag_us"] * 1e-6
    assert read.read == {"sensor_lag_us"}
    with pytest.raises(KeyError):
        si["feedback"]                            # a choice among words has no SI value


def test_values_that_cannot_be_hashed_are_not_remembered():
    memo = Memo()
    data = {"rows": [1, 2]}
    assert memo.call("k", {"data": data}, lambda values: len(values["data"]["rows"])) == 2
    assert not memo.entries


@pytest.mark.parametrize("name, panel", [("kalman_noise", SCOPE), ("kalman_noise", POLE_MAP),
                                         ("adaptive_filter", SCOPE), ("thrust_liftoff", SCOPE),
                                         ("lqg_vs_pid", POLE_MAP), ("rotor_at_speed", POLE_MAP)])
def test_a_control_a_panel_never_reads_leaves_it_unchanged(name, panel):
    """What ``ReadValues`` finds is all a panel depends on: moving any other control changes nothing."""
    exercise = get(name)
    values = exercise.resolve({})
    read = ReadValues(values)
    before = _last(exercise.analyse_panel(read, panel))
    unread = [p for p in exercise.parameters if p.name not in read.read and not p.choices]
    assert unread, "the panel reads every control"
    for parameter in unread:
        moved = parameter.maximum if parameter.default != parameter.maximum else parameter.minimum
        after = _last(exercise.analyse_panel(exercise.resolve({**values, parameter.name: moved}), panel))
        assert after.readouts == before.readouts, parameter.name
        assert after.poles.keys() == before.poles.keys(), parameter.name
        for key in before.poles:
            np.testing.assert_array_equal(after.poles[key], before.poles[key])


# -- cheaper maths ---------------------------------------------------------------------------------
def _radius(A: np.ndarray) -> float:
    return float(np.max(np.abs(np.linalg.eigvals(A))))


def test_first_instability_is_where_the_affine_loop_leaves_the_unit_circle():
    axis = kalman_noise.setup(get("kalman_noise").resolve({}))
    low, high = 0.25, 10.0
    A_low, A_high = axis.loop_matrix(low), axis.loop_matrix(high)
    edge = analysis.first_instability(A_low, A_high, low, high)
    assert low < edge < high

    def at(g: float) -> np.ndarray:
        return A_low + (g - low) / (high - low) * (A_high - A_low)
    assert _radius(at(edge * (1 - 1e-6))) < 1.0 < _radius(at(edge * (1 + 1e-6)))
    np.testing.assert_allclose(at(2.0), axis.loop_matrix(2.0), rtol=1e-9, atol=1e-12)   # affine indeed
    # stable over the whole range: the end
    assert analysis.first_instability(A_low, A_low, low, high) == high


def test_largest_gain_factor_agrees_with_a_fine_scan():
    """The gain criterion (RMS displacement at or below the sensor's σ) by Brent's method below the
    stability edge agrees with a scan of the RMS on a 1e-3 grid."""
    values = get("kalman_noise").resolve({})
    axis = kalman_noise.setup(values)
    limits = kalman_noise.largest_gain_factors(values)
    for source in ("measured", "estimated"):
        g = limits[source]
        below = axis.noise_rms(source == "estimated", g - 1e-3)["x_m"]
        above = axis.noise_rms(source == "estimated", g + 1e-3)["x_m"]
        assert below <= axis.sensor_noise_m < above, (source, g)


def test_largest_stable_gain_is_the_edge_of_the_affine_loop():
    values = sensor_placement.EXERCISE.resolve({"sensor_offset_mm": 0.0})
    g, _ = sensor_placement.largest_stable_gain(values)
    assert sensor_placement.stable(sensor_placement.loop(values, g * (1 - 1e-6)))
    assert not sensor_placement.stable(sensor_placement.loop(values, g * (1 + 1e-6)))


# -- a tab computes a panel only while it is shown ---------------------------------------------------
PORT = 8128
NOISE = "Position sensor noise σ [µm]"
PLACEHOLDER = "Computed when this tab is shown"


def _content(tab: RawTab, uuid: str) -> str:
    return tab.elements[uuid]["content"] or ""


async def _panels_on_demand() -> None:
    tab = await RawTab().connect(f"http://127.0.0.1:{PORT}")
    def placeholders() -> list[str] | None:
        found = [uuid for uuid, e in tab.elements.items() if PLACEHOLDER in (e["content"] or "")]
        return found if len(found) == 2 else None
    waiting = await tab.wait_for(placeholders, 120)
    assert waiting, "the Pole map and the Analysis tab wait to be shown"
    beacons = {}
    for label in ("panel shown: Analysis", "panel hidden: Analysis", "panel shown: Pole map"):
        beacons[label] = await tab.wait_for(lambda label=label: tab.find("GuiButtonMessage", label))
    slider = tab.find("GuiSliderMessage", NOISE)
    readouts = tab.find_containing("GuiMarkdownMessage", "| quantity | value | unit |")
    analysis_readouts = waiting[1]
    for value in (2.0, 2.5):                                   # moves with the Scope shown
        before = _content(tab, readouts)
        await tab.set_value(slider, value)
        assert await tab.wait_for(lambda before=before: _content(tab, readouts) != before, 30)
    await asyncio.sleep(1.0)
    assert PLACEHOLDER in _content(tab, analysis_readouts), "computed while hidden"
    assert not any("poles" in (e["label"] or "").lower() for e in tab.elements.values()
                   if e["type"] == "GuiUplotMessage"), "pole maps drawn while hidden"

    await tab.set_value(beacons["panel shown: Analysis"], True)           # opened: computed now
    assert await tab.wait_for(lambda: "Largest gain factor, measured" in _content(tab, analysis_readouts)
                              and "gain margin" in _content(tab, analysis_readouts), 60)
    shown = _content(tab, analysis_readouts)
    await tab.set_value(slider, 3.0)                          # while shown, it follows the slider
    assert await tab.wait_for(lambda: _content(tab, analysis_readouts) != shown
                              and "computing" not in _content(tab, analysis_readouts), 60)

    await tab.set_value(beacons["panel hidden: Analysis"], True)          # hidden: no longer
    await asyncio.sleep(0.5)
    hidden = _content(tab, analysis_readouts)
    await tab.set_value(slider, 1.5)
    await asyncio.sleep(3.0)
    assert _content(tab, analysis_readouts) == hidden, "computed while hidden"

    await tab.set_value(beacons["panel shown: Pole map"], True)
    assert await tab.wait_for(lambda: tab.find_containing("GuiMarkdownMessage", "f_n [Hz]"), 60)
    assert sum("poles" in (e["label"] or "").lower() for e in tab.elements.values()
               if e["type"] == "GuiUplotMessage") == 2
    await tab.close()


@pytest.mark.classroom
def test_a_panel_is_computed_only_while_it_is_shown(tmp_path):
    with lab_process(PORT, "--exercise", "kalman_noise", data_dir=tmp_path, log=tmp_path / "server.log"):
        run_async(_panels_on_demand())


# -- remembered pieces give the figures of a fresh computation --------------------------------------
def _forget(module) -> None:
    """Empty every memo of a module's ``remembered`` functions."""
    for function in vars(module).values():
        memo = getattr(function, "memo", None)
        if isinstance(memo, Memo):
            memo.entries.clear()
            memo.read_sets.clear()


@pytest.mark.parametrize("name, changes, neighbour", [
    ("ekf_disturbance", {}, {"disturbance_step_n": 440.0}),
    ("ekf_disturbance", {"disturbance_step_n": 250.0, "filter_q_force": 3.0, "sweep_amplitude_um": 80.0},
     {"disturbance_step_n": 300.0}),
    ("ekf_disturbance", {"experiment": "gap_sweep", "feedforward": "on", "sweep_load_n": -150.0, "seed": 3},
     {"sweep_load_n": 100.0}),
    ("self_sensing", {}, {"gap_2_mm": 6.5}),
    ("self_sensing", {"gap_1_mm": 3.5, "battery_voltage_v": 12.0, "sigma_current_ma": 2.0}, {"gap_1_mm": 3.6}),
    ("self_sensing", {"trajectory": "fixed at gap 2", "resistance_ratio": 1.05, "gap_2_mm": 7.0,
                      "feedback": "self-sensing estimate ŝ"}, {"gap_2_mm": 6.0}),
])
def test_split_panels_with_remembered_pieces_show_what_a_fresh_analysis_shows(name, changes, neighbour):
    """After a move from a neighbouring setting (its pieces remembered, some of them reused), every
    panel's readouts, poles, notes and plots are those of the analysis computed afresh."""
    exercise = get(name)
    module = importlib.import_module(type(exercise).__module__)
    values = exercise.resolve(changes)
    _last(exercise.analyse(exercise.resolve({**changes, **neighbour})))
    reused = _last(exercise.analyse(dict(values)))
    _forget(module)
    fresh = _last(exercise.analyse(dict(values)))
    assert [label for label, _, _ in reused.readouts] == [label for label, _, _ in fresh.readouts]
    np.testing.assert_array_equal([value for _, value, _ in reused.readouts],
                                  [value for _, value, _ in fresh.readouts])
    assert reused.notes == fresh.notes and reused.poles.keys() == fresh.poles.keys()
    for key in fresh.poles:
        np.testing.assert_array_equal(reused.poles[key], fresh.poles[key])
    assert [plot.title for plot in reused.plots] == [plot.title for plot in fresh.plots]
    for before, after in zip(reused.plots, fresh.plots):
        np.testing.assert_array_equal(before.x, after.x)
        for (_, y_before, _), (_, y_after, _) in zip(before.series, after.series):
            np.testing.assert_array_equal(y_before, y_after)
