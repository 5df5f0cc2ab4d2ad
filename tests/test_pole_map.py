"""The Pole map tab (issue 11, defects 3, 9 and 15, and the root locus), without a browser:
every exercise declares which of the lab's four categories each of its pole sets is, each category
keeps its colour in every exercise, both maps' ranges hold every pole they draw, the
modes are numbered with their frequency and damping, and the root locus at the current
factor is the closed loop the exercise reports."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from app.panels import pole_map
from lab_modules import analysis
from lab_modules.evaluation import poles as pole_sets
from lab_modules.evaluation import root_locus
from lab_modules.exercises import Analysis, PoleCategory, get, sensor_placement
from lab_modules.exercises.ekf_parameters import linear_axis, linear_poles
from lab_modules.plants.radial_bearing import RIG
from tests.example_exercise import contract_exercises

CONTRACT = contract_exercises()          # the registered exercises and the tests' minimal example
EXERCISES = tuple(CONTRACT)
#: the exercises with a common gain factor and the pole set it moves
LOCI = {"kalman_noise": ("gain_factor", "closed loop"), "sensor_placement": ("gain_factor", "closed loop"),
        "ekf_disturbance": ("pid_gain", "closed loop (linearised)"),
        "ekf_parameters": ("pid_gain", "closed loop (linear, rated k_i, k_x)"),
        "lqg_vs_pid": ("pid_gain", "PID loop with filter")}


def first_analysis(exercise, values) -> Analysis:
    result = exercise.analyse(values)
    return result if isinstance(result, Analysis) else next(iter(result))


@pytest.fixture(scope="module")
def defaults() -> dict:
    """Each exercise's default values and pole sets (the quick analysis)."""
    out = {}
    for name in EXERCISES:
        exercise = CONTRACT[name]
        values = exercise.resolve()
        out[name] = (exercise, values, first_analysis(exercise, values).poles)
    return out


def drawn(data) -> np.ndarray:
    """The points (Re + j Im) a map draws, the imaginary axis included (last column)."""
    x, sets = data[0], np.vstack(data[1:])
    rows, columns = np.nonzero(np.isfinite(sets))
    return x[columns] + 1j * sets[rows, columns]


def test_categories_have_one_colour_each_and_a_legend():
    colours = [c.color for c in pole_sets.CATEGORIES]
    assert len(set(colours)) == len(colours) == 4 and pole_map.LOCUS_COLOR not in colours
    legend = pole_map.legend_markdown()
    assert all(c.color in legend and c.meaning in legend for c in pole_sets.CATEGORIES)


@pytest.mark.parametrize("name", EXERCISES)
def test_every_pole_set_has_a_declared_category(defaults, name):
    """``Exercise.pole_categories``: the exercise declares the category of each set it reports,
    and no set it does not report; the pole view draws each set in the declared category."""
    exercise, values, poles = defaults[name]
    declared = exercise.pole_categories(values)
    assert set(declared) == set(poles), (name, set(poles) ^ set(declared))
    assert all(isinstance(kind, PoleCategory) for kind in declared.values()), declared
    pole_view = pole_sets.view(exercise, values, poles)
    assert {set_name: c.name for set_name, c in pole_view.categories.items()} == {
        set_name: kind.value for set_name, kind in declared.items()}


def test_a_set_named_after_the_values_is_declared_at_those_values():
    """self_sensing names its coil poles after the gaps: moved gaps, the same declaration."""
    exercise = get("self_sensing")
    values = exercise.resolve({"gap_1_mm": 3.25, "gap_2_mm": 7.5})
    poles = first_analysis(exercise, values).poles
    assert set(exercise.pole_categories(values)) == set(poles) == {"coil −R/L at 3.25 mm", "coil −R/L at 7.5 mm"}


def test_a_set_name_means_one_category_in_every_exercise():
    """Each category has one colour in every exercise; so has each set name."""
    seen: dict[str, tuple[str, PoleCategory]] = {}
    for name, exercise in CONTRACT.items():
        for set_name, kind in exercise.pole_categories(exercise.resolve()).items():
            first = seen.setdefault(set_name, (name, kind))
            assert first[1] == kind, (set_name, first, (name, kind))


def test_categories_are_the_lab_pole_categories_in_order():
    assert [c.name for c in pole_sets.CATEGORIES] == [kind.value for kind in PoleCategory]


@pytest.mark.parametrize("set_name, expected", [
    ("open-loop plant", "plant"), ("open-loop plant (linearised, 14.8 mm)", "plant"), ("coil −R/L at 4 mm", "plant"),
    ("closed loop", "closed loop"), ("PID loop with filter", "closed loop"), ("lead-lag loop (linearised)", "closed loop"),
    ("feedback-linearised loop (eq. 2.29)", "closed loop"), ("closed loop without G(s)", "closed loop"),
    ("filter error", "filter error"), ("Kalman filter error", "filter error"),
    ("ADALINE weight error (rotor's weight)", "filter error"), ("LQG regulator", "regulator")])
def test_set_names_map_to_the_intended_category(set_name, expected):
    assert pole_sets.category(set_name).name == expected


@pytest.mark.parametrize("name", EXERCISES)
def test_same_category_same_colour_in_every_exercise(defaults, name):
    exercise, values, poles = defaults[name]
    for _, options in pole_map.charts(pole_sets.view(exercise, values, poles)):
        for series in options["series"][1:-1]:
            if series["label"] in poles:
                assert series["stroke"] == pole_sets.category(series["label"]).color


@pytest.mark.parametrize("name", EXERCISES)
def test_both_maps_range_over_every_pole_they_draw(defaults, name):
    """Defect 3: explicit x and y ranges that hold every pole (and the locus), with margin;
    the map of all poles draws every pole of every set."""
    exercise, values, poles = defaults[name]
    for k, (data, options) in enumerate(pole_map.charts(pole_sets.view(exercise, values, poles))):
        points = drawn(data)
        (x_low, x_high), y = options["scales"]["x"]["range"], options["scales"]["y"]
        assert x_low < points.real.min() and x_high > points.real.max(), (name, k)
        assert y["min"] < points.imag.min() and y["max"] > points.imag.max(), (name, k)
        assert np.all(np.diff(data[0]) >= 0)                  # uPlot needs a sorted x
        if k == 1:
            everything = np.concatenate([np.asarray(p, dtype=complex) for p in poles.values()])
            assert all(np.min(np.abs(points - p)) < 1e-9 * max(abs(p), 1.0) for p in everything), name


def test_maglev_tracking_shows_the_unstable_open_loop_pole(defaults):
    exercise, values, poles = defaults["maglev_tracking"]
    unstable = max(p.real for p in poles["open-loop plant (linearised, 14.8 mm)"])
    assert unstable == pytest.approx(36.4, abs=0.1)
    for _, options in pole_map.charts(pole_sets.view(exercise, values, poles)):
        assert options["scales"]["x"]["range"][1] > unstable * 1.05


def test_ekf_parameters_shows_closed_loop_and_filter_error(defaults):
    """Defect 9: the closed loop (stable at the defaults) and the filter error poles, the latter
    cross-checked with scipy's Riccati solver (K = P Cᵀ (C P Cᵀ + R)⁻¹ of the predicted P)."""
    _, values, poles = defaults["ekf_parameters"]
    categories = {pole_sets.category(name).name for name in poles}
    assert categories == {"plant", "closed loop", "filter error"}
    closed = poles["closed loop (linear, rated k_i, k_x)"]
    assert np.all(closed.real < 0)
    axis = linear_axis(values)
    A, C = np.asarray(axis.model.A), np.asarray(axis.model.C)
    P = scipy.linalg.solve_discrete_are(A.T, C.T, axis.filter_Q, axis.filter_R)
    K = P @ C.T @ np.linalg.inv(C @ P @ C.T + axis.filter_R)
    expected = analysis.z_to_s(np.linalg.eigvals(A - A @ K @ C), axis.model.dt)
    got = poles["filter error (x, v, i at rated k_i, k_x)"]
    assert np.max(np.abs(np.sort_complex(got) - np.sort_complex(expected))) < 1e-6 * np.max(np.abs(expected))


def test_ekf_disturbance_shows_closed_loop_and_filter_error(defaults):
    """The linearised closed loop (stable at the defaults, the same as ekf_parameters' linear loop
    on the same sliders) beside the EKF's filter error poles."""
    _, values, poles = defaults["ekf_disturbance"]
    assert {pole_sets.category(name).name for name in poles} == {"plant", "closed loop", "filter error"}
    closed = poles[LOCI["ekf_disturbance"][1]]
    assert np.all(closed.real < 0)
    expected = linear_poles(linear_axis(values))["closed loop (linear, rated k_i, k_x)"]
    assert np.max(np.abs(np.sort_complex(closed) - np.sort_complex(expected))) < 1e-9 * np.max(np.abs(expected))


def test_modes_number_every_real_pole_and_pair_with_frequency_and_damping():
    poles = {"closed loop": np.array([-3 + 4j, -3 - 4j, -10.0]), "open-loop plant": np.array([5.0, -5.0])}
    modes = pole_sets.modes(poles)
    assert [m.set_name for m in modes] == ["open-loop plant"] * 2 + ["closed loop"] * 2   # plant first
    pair = next(m for m in modes if not m.is_real)
    assert pair.pole == -3 + 4j and pair.damping == pytest.approx(0.6)
    assert pair.natural_hz == pytest.approx(5 / (2 * np.pi)) and pair.kind == "oscillation"
    assert modes[0].kind.startswith("unstable") and modes[0].damping == -1.0
    table = pole_map.table_markdown(poles)
    assert len(table.splitlines()) == 2 + 4 and "-3 ± 4j" in table and "| 0.6 |" in table


def test_mode_labels_do_not_overlap():
    poles = {"plant": np.array([-100.0, -99.0, -98.0, -50.0, 0.5, 1.0, 40.0])}
    modes = pole_sets.modes(poles)
    x_range = (-110.0, 45.0)
    splits, texts = pole_map.top_axis_labels(modes, x_range)
    px = np.array(splits) * pole_map.LABEL_PX / (x_range[1] - x_range[0])
    widths = np.array([len(t) for t in texts]) * pole_map.CHAR_PX
    assert np.all(np.diff(px) >= (widths[:-1] + widths[1:]) / 2)
    shown = sum(int(t.split("+")[1]) if "+" in t else 0 for t in texts) + sum(
        len([n for n in t.split(",") if not n.startswith("+")]) for t in texts)
    assert shown == len(modes)


@pytest.mark.parametrize("name", EXERCISES)
def test_locus_only_where_there_is_a_common_gain_factor(name):
    assert CONTRACT[name].locus == LOCI.get(name)


@pytest.mark.parametrize("name", sorted(LOCI))
@pytest.mark.parametrize("factor_share", [None, 0.35])
def test_locus_at_the_current_factor_is_the_reported_closed_loop(name, factor_share):
    """The locus points at the current factor (default, and another value of the range) are the
    closed-loop poles the exercise's analysis reports; a point between the ends, where the
    interpolated state matrix is used, equals a direct computation there."""
    exercise = get(name)
    parameter_name, set_name = exercise.locus
    parameter = next(p for p in exercise.parameters if p.name == parameter_name)
    values = exercise.resolve()
    if factor_share is not None:
        values = exercise.resolve({parameter_name: parameter.minimum
                                   + factor_share * (parameter.maximum - parameter.minimum)})
    reported = np.sort_complex(np.asarray(first_analysis(exercise, values).poles[set_name]))
    factors = np.array([parameter.minimum, values[parameter_name], parameter.maximum])
    interpolated = np.sort_complex(root_locus.locus_poles(exercise, values, factors)[1])
    assert np.max(np.abs(interpolated - reported)) <= 1e-6 * np.max(np.abs(reported))
    path = root_locus.locus(exercise, values)
    assert path.poles.shape == (root_locus.LOCUS_POINTS, reported.size)
    assert path.factors[0] == parameter.minimum and path.factors[-1] == pytest.approx(parameter.maximum)
    middle = float(path.factors[root_locus.LOCUS_POINTS // 2])
    (A,), T = exercise.locus_matrices(values, (middle,))
    direct = np.sort_complex(analysis.z_to_s(np.linalg.eigvals(A), T))
    assert np.max(np.abs(np.sort_complex(path.poles[root_locus.LOCUS_POINTS // 2]) - direct)) <= 1e-6 * np.max(
        np.abs(direct))


def test_locus_is_cached_per_setting_and_ignores_the_factor_itself():
    exercise = get("kalman_noise")
    values = exercise.resolve()
    first = root_locus.locus(exercise, values)
    assert root_locus.locus(exercise, {**values, "gain_factor": 2.0}).poles is first.poles
    assert root_locus.locus(exercise, {**values, "sensor_lag_us": 100.0}).poles is not first.poles


@pytest.mark.parametrize("name", EXERCISES)
def test_mode_names_are_aligned_with_the_pole_sets(defaults, name):
    """``Exercise.mode_names``: one name (or None) per pole of a reported set, a conjugate pair
    named alike; every pole of a named plant set has its name (the generic kind stays for the rest)."""
    exercise, values, poles = defaults[name]
    names = pole_sets.view(exercise, values, poles).names
    for set_name, given in names.items():
        ps = np.asarray(poles[set_name], dtype=complex)
        assert len(given) == ps.size, (name, set_name)
        for p, label in zip(ps, given):
            twin = np.argmin(np.abs(ps - np.conj(p)))
            assert given[twin] == label, (name, set_name, p)
        if pole_sets.category(set_name).name == "plant":
            assert all(given), (name, set_name, given)


def test_sensor_placement_names_the_mode_that_goes_unstable_first():
    """Just above the largest stable gain with the external sensor (the claim's setting), the pole
    table's most unstable closed-loop mode is the bending mode the claim names (mode 3, the 2nd
    bending mode), and it is marked unstable."""
    exercise = get("sensor_placement")
    claim = next(c for c in exercise.claims if c.metric == "first_unstable_mode_external")
    values = exercise.resolve({"sensor_offset_mm": sensor_placement.EXTERNAL_OFFSET_MM})
    gain, first = sensor_placement.largest_stable_gain(values)
    assert claim.accept[0] <= first <= claim.accept[1]
    values = exercise.resolve({**values, "gain_factor": gain + 0.02})
    pole_view = pole_sets.view(exercise, values, first_analysis(exercise, values).poles)
    closed = [m for m in pole_sets.modes(pole_view.poles, pole_view.names) if m.set_name == "closed loop"]
    growing = max(closed, key=lambda m: m.pole.real)
    assert growing.pole.real > 0 and growing.name == sensor_placement.mode_name(first - 1)
    assert growing.name == "rotor mode 3 (2nd bending)" and "bending" in claim.quantity + claim.paper
    assert f"| {growing.number} |" in pole_map.table_markdown(pole_view)
    assert "rotor mode 3 (2nd bending) (unstable)" in pole_map.table_markdown(pole_view)


def test_sensor_placement_mode_names_match_the_beam_model(defaults):
    """The open-loop plant's modes carry the name of the beam model's mode of that frequency: each
    bending mode's f_n = |s|/2π lies within 2 % of its free natural frequency (the magnet's negative
    stiffness k_x shifts it a little), the rigid mode (0 Hz free, on the ball bearing) is the real
    pair (nearly ±) the magnet makes unstable."""
    exercise, values, poles = defaults["sensor_placement"]
    names = pole_sets.view(exercise, values, poles).names
    free = sensor_placement.rotor(values["modal_damping_percent"] / 100).natural_frequencies_hz(int(values["modes"]))
    plant = np.asarray(poles["open-loop plant"], dtype=complex)
    for j, f in enumerate(free):
        mine = plant[[label == sensor_placement.mode_name(j) for label in names["open-loop plant"]]]
        assert mine.size == 2, j
        if j == 0:
            assert np.all(mine.imag == 0) and mine.real.max() > 0 and mine.real.sum() == pytest.approx(0, abs=1e-4 * np.abs(mine).max())
        else:
            assert np.abs(mine) / (2 * np.pi) == pytest.approx([f, f], rel=0.02)
            others = np.delete(free, j)
            assert np.min(np.abs(others - abs(mine[0]) / (2 * np.pi))) > 0.2 * f   # no other mode that close
    closed_named = [label for label in names["closed loop"] if label]
    rotor_names = {sensor_placement.mode_name(j) for j in range(free.size)}
    assert rotor_names <= set(closed_named)         # the rest: PID, lags (``mode_matrices``)
    assert len(closed_named) == len(names["closed loop"])


def test_radial_axis_plant_poles_are_named_by_their_physics(defaults):
    _, _, poles = defaults["kalman_noise"]
    names = pole_sets.view(get("kalman_noise"), defaults["kalman_noise"][1], poles).names["open-loop plant"]
    by_name = dict(zip(names, np.asarray(poles["open-loop plant"], dtype=complex)))
    assert by_name["rotor position (unstable magnet pole)"].real > 0
    assert by_name["coil current (amplifier lag T_a)"] == pytest.approx(-1 / RIG.amplifier_lag_s)
    table = pole_map.table_markdown(pole_sets.view(get("kalman_noise"), defaults["kalman_noise"][1], poles))
    assert "rotor position (unstable magnet pole) |" in table and "position sensor lag T_mx" in table
    assert "real, τ =" not in table and "PID integrator" in table   # the loops' poles named too (mode_matrices)
