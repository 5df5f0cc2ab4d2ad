"""Margins and sensitivity of loops broken at the plant input (issue 11): the lab's own
crossover search against python-control's ``margin`` on a textbook loop, against the
closed loop's stability under scaled gains on the bearing loop (where ``margin``'s
polynomial method misses the crossings), and |S|max against a direct evaluation of
1 / |1 + C (zI - A)^-1 B + D| on a dense grid; all to 1 %."""

from __future__ import annotations

import warnings

import control
import numpy as np
import pytest

from lab_modules import analysis
from lab_modules.evaluation.margins import MARGIN_GRID_POINTS, margin_view
from lab_modules.exercises import get
from lab_modules.exercises.kalman_noise import setup
from lab_modules.loop_sensitivity import frequency_grid, iso_zone, loop_margins
from tests.example_exercise import contract_exercises


def _direct_sensitivity_peak(loop: control.StateSpace, omega: np.ndarray) -> float:
    A, B, C, D = (np.asarray(M) for M in (loop.A, loop.B, loop.C, loop.D))
    z = np.exp(1j * omega * loop.dt) if loop.dt else 1j * omega
    identity = np.eye(A.shape[0])
    L = np.array([(C @ np.linalg.solve(zk * identity - A, B) + D)[0, 0] for zk in z])
    return float(np.max(1.0 / np.abs(1.0 + L)))


def test_textbook_loop_agrees_with_control_margin():
    loop = control.ss(control.tf([4.0], [1.0, 3.0, 2.0, 0.0]))   # 4 / (s (s + 1) (s + 2))
    gm, pm, _, wcp = control.margin(loop)
    m = loop_margins(loop, np.logspace(-2, 2, 2000))
    assert m.gain_margin == pytest.approx(gm, rel=0.01)
    assert m.phase_margin_deg == pytest.approx(pm, rel=0.01)
    assert m.gain_crossover_rad_s == pytest.approx(wcp, rel=0.01)
    assert m.sensitivity_peak == pytest.approx(_direct_sensitivity_peak(loop, np.logspace(-2, 2, 20000)), rel=0.01)


@pytest.mark.parametrize("feedback", ["measured", "estimated"])
def test_bearing_loop_margins_bracket_stability(feedback):
    axis = setup(get("kalman_noise").resolve({"feedback": feedback}))
    loop = axis.loop_at_plant_input()
    m = loop_margins(loop)

    def stable(g: float) -> bool:
        return bool(np.max(np.abs(control.feedback(g * loop, 1).poles())) < 1.0)
    assert m.stable and stable(1.0)
    for margin in (m.gain_margin, m.gain_margin_down):
        assert stable(margin * 0.99 if margin > 1 else margin * 1.01)
        assert not stable(margin * 1.01 if margin > 1 else margin * 0.99)
    # the broken loop closes to the exercise's loop: same spectral radius
    assert max(abs(control.feedback(loop, 1).poles())) == pytest.approx(
        max(abs(analysis.loop_poles(axis.loop()))), rel=1e-6)
    omega = frequency_grid(loop, points=20000)
    assert m.sensitivity_peak == pytest.approx(_direct_sensitivity_peak(loop, omega), rel=0.01)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, pm_frd, _, _ = control.margin(control.frd(loop, omega[::4]))
    assert m.phase_margin_deg == pytest.approx(pm_frd, rel=0.01)
    assert m.zone == iso_zone(m.sensitivity_peak)


def test_iso_zones_and_the_analysis_tab_view():
    assert [iso_zone(p) for p in (2.9, 3.5, 4.5, 5.5)] == ["A", "B", "C", "D"]
    readouts, plots, _ = margin_view(get("lqg_vs_pid"), get("lqg_vs_pid").resolve({}))
    labels = [label for label, _, _ in readouts]
    assert any("PID: |S|max, ISO 14839-3 zone" in label for label in labels)
    units = {unit for label, _, unit in readouts if label.startswith("PID: ")}
    assert units == {"×", "dB", "°", "Hz"}
    assert len(plots) == 3 and all(p.log_x for p in plots)
    # |S| drawn in dB (as AMB engineers and ISO 14839-3 read it), its peak at the readout's dB value
    sens = plots[2]
    assert sens.y_label == "|S| [dB]" and not sens.log_y
    curves = {label: y for label, y, _ in sens.series}
    loop = get("lqg_vs_pid").open_loops(get("lqg_vs_pid").resolve({}))["PID"]
    omega = 2 * np.pi * sens.x
    direct = -20 * np.log10(np.abs(1 + np.squeeze(control.frequency_response(loop, omega).complex)))
    assert np.allclose(curves["|S| PID"], direct, atol=1e-9)
    peak_db = next(value for label, value, unit in readouts if label.startswith("PID: |S|max") and unit == "dB")
    assert np.nanmax(curves["|S| PID"]) == pytest.approx(peak_db, abs=0.01)
    limits = sorted(float(y[0]) for label, y, _ in sens.series if label.startswith("zone limit"))
    assert limits == pytest.approx([9.542, 12.041, 13.979], abs=1e-3)
    assert margin_view(get("self_sensing"), get("self_sensing").resolve({})) == (
        [], [], [get("self_sensing").no_feedback_loop])


# -- every exercise with a feedback loop (issue 11) ------------------------------------------------
#: Settings besides the defaults whose loops differ in structure (another controller, filter or
#: feedback source): each gets the same checks.
VARIANTS = {
    "kalman_noise": [{}],
    "lqg_vs_pid": [{}],
    "ekf_parameters": [{}, {"feedback": "estimated", "reference_offset_um": 100.0}],
    "ekf_disturbance": [{}, {"feedforward": "on"}, {"feedback": "measured"}],
    "sensor_placement": [{}, {"feedback": "estimated"}, {"sensor_offset_mm": 0.0}],
    "maglev_tracking": [{}, {"controller": "lead-lag"}, {"filter": "continuous-time"},
                        {"filter": "continuous-time-Rdt"}],
    "maglev_tuning": [{}],
    "thrust_liftoff": [{}, {"feedback": "estimated"}, {"current_loop": "off"}],
    "adaptive_filter": [{}, {"feedback": "measured"}, {"feedback": "ekf"}],
    "stiffness_map": [{}],
    "rotor_at_speed": [{}, {"feedback": "estimated"}, {"sensor_offset_mm": 60.0}],
    "self_sensing": [{"feedback": "self-sensing estimate ŝ", "trajectory": "fixed at gap 1"}],
}
CASES = [(name, settings) for name, variants in VARIANTS.items() for settings in variants]


def _closed_loop_radius(loop, gain: float) -> float:
    """Spectral radius (largest real part if continuous) of 1 / (1 + g L) closed: A - g B (1 + g D)^-1 C."""
    A, B, C, D = (np.asarray(M, dtype=float) for M in (loop.A, loop.B, loop.C, loop.D))
    poles = np.linalg.eigvals(A - gain * B @ np.linalg.solve(np.eye(D.shape[0]) + gain * D, C))
    return float(np.max(np.abs(poles))) if loop.dt else float(np.max(poles.real))


def _stable(loop, gain: float) -> bool:
    return _closed_loop_radius(loop, gain) < (1.0 if loop.dt else 0.0)


def _stability_edge(loop, upwards: bool, tolerance: float = 1e-3) -> float:
    """The common gain factor, from 1 up (or down), where the closed loop first loses stability:
    bisection on the closed loop's poles (inf / 0 when none before 1e4 / 1e-4)."""
    inside, step = 1.0, (2.0 if upwards else 0.5)
    outside = inside * step
    while _stable(loop, outside):
        inside, outside = outside, outside * step
        if not 1e-4 < outside < 1e4:
            return np.inf if upwards else 0.0
    while abs(outside / inside - 1.0) > tolerance:
        middle = np.sqrt(inside * outside)
        inside, outside = (middle, outside) if _stable(loop, middle) else (inside, middle)
    return inside


def test_every_exercise_declares_its_loops_or_says_why_not():
    """An exercise either opens its feedback loops (``open_loops``) or states why it has none, so a
    new exercise with a loop cannot leave the Analysis tab without margins by forgetting."""
    for name, exercise in contract_exercises().items():
        loops = exercise.open_loops(exercise.resolve({}))
        assert bool(loops) != bool(exercise.no_feedback_loop), name
        assert name in VARIANTS or not loops, f"{name}: add its loops to VARIANTS in this test"


@pytest.mark.parametrize("name, settings", CASES, ids=[f"{n}-{'-'.join(map(str, s.values())) or 'defaults'}"
                                                       for n, s in CASES])
def test_margins_of_every_loop(name, settings):
    exercise = get(name)
    values = exercise.resolve(settings)
    dense = None
    for label, loop in exercise.open_loops(values).items():
        m = loop_margins(loop, frequency_grid(loop, points=MARGIN_GRID_POINTS))
        dense = frequency_grid(loop, points=20000)
        # |S|max against 1 / |1 + C (zI - A)^-1 B + D| on a dense grid
        assert m.sensitivity_peak == pytest.approx(_direct_sensitivity_peak(loop, dense), rel=0.01), label
        assert m.zone == (iso_zone(m.sensitivity_peak) if m.stable else "D")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            gm_frd, pm_frd, _, wc_frd = control.margin(control.frd(loop, dense[::4]))
            gm_ss, _, _, _ = control.margin(loop)
        # phase margin and crossover: python-control on the frequency response (valid for any loop)
        assert m.phase_margin_deg == pytest.approx(abs(pm_frd), rel=0.01), label
        assert m.gain_crossover_rad_s == pytest.approx(wc_frd, rel=0.01), label
        # python-control's gain margin is one of the two (it picks one; on the state space it can
        # misread an open-loop unstable loop, so only a value that matches either is held to 1 %)
        margins = [g for g in (m.gain_margin, m.gain_margin_down) if 0 < g < np.inf]
        assert min(abs(gm_frd / g - 1) for g in margins) < 0.01, (label, gm_frd, margins)
        if min(abs(gm_ss / g - 1) for g in margins) < 0.05:
            assert min(abs(gm_ss / g - 1) for g in margins) < 0.01
        # the gain margins are where closing the loop at a common gain factor loses stability
        if m.stable:
            assert _stable(loop, 1.0)
            up, down = _stability_edge(loop, True), _stability_edge(loop, False)
            assert (m.gain_margin == up == np.inf) or m.gain_margin == pytest.approx(up, rel=0.01), label
            assert (m.gain_margin_down == down == 0.0) or m.gain_margin_down == pytest.approx(down, rel=0.01)
        else:
            assert not _stable(loop, 1.0)
            for g in margins:          # each reported margin is a stability edge
                assert _stable(loop, 0.99 * g) != _stable(loop, 1.01 * g), (label, g)
    assert dense is not None, f"{name} declares no open loop"


def test_broken_loops_close_to_the_exercises_own_loops():
    """Closing L at gain 1 gives the loops the exercises simulate and analyse on their own."""
    from lab_modules.exercises import sensor_placement, thrust_liftoff
    from lab_modules.loops.thrust_liftoff_linear import linear_loop

    values = get("thrust_liftoff").resolve({"feedback": "estimated"})
    loop = next(iter(get("thrust_liftoff").open_loops(values).values()))
    assert _closed_loop_radius(loop, 1.0) == pytest.approx(
        np.max(np.abs(linear_loop(thrust_liftoff.setup(values)).poles())), rel=1e-9)
    for settings in ({}, {"sensor_offset_mm": 0.0}):
        values = get("sensor_placement").resolve(settings)
        loop = sensor_placement.loop_at_plant_input(values)
        assert _closed_loop_radius(loop, 1.0) == pytest.approx(
            np.max(np.abs(sensor_placement.loop(values).poles())), rel=1e-9)
        # the exercise's own search (raising the PID gain from the smallest that levitates) ends
        # where the margin says: gain factor × gain margin
        largest, _ = sensor_placement.largest_stable_gain(values)
        m = loop_margins(loop, frequency_grid(loop, points=MARGIN_GRID_POINTS))
        edge = m.gain_margin if m.stable else m.gain_margin_down
        assert values["gain_factor"] * edge == pytest.approx(largest, abs=0.006)


def test_analysis_charts_follow_plots_that_change_between_results():
    """A later analysis result may hold other plots than the first (stiffness_map yields 4, then 8,
    and the margin plots follow them): each chart takes its plot's series and title, not only the
    data, and missing charts are added (before, the margin charts drew other plots' data)."""
    import contextlib

    from app.panels.plots import AnalysisPlots
    from app.panels.plots import plot_shape as _plot_shape
    from lab_modules.exercises import Plot

    class Handle:
        def __init__(self, data, **options):
            self.data, self.removed = data, False
            self.title, self.series = options["title"], options["series"]
            self.order = options.get("order", 0.0)       # a replacing chart takes the replaced one's place

        def remove(self):
            self.removed = True

    class Stub:
        def __init__(self):
            self.plots, self.plot_shapes = [], []
            self.container, self.atomic = contextlib.nullcontext(), contextlib.nullcontext
            self.gui = type("Gui", (), {"add_uplot": staticmethod(lambda data, **options: Handle(data, **options))})()

    def plot(title: str) -> Plot:
        return Plot(title, "x [1]", "y [1]", np.arange(3.0), ((title, np.ones(3), "#000000"),))
    stub = Stub()
    AnalysisPlots.update(stub, [plot("a"), plot("margin")])
    AnalysisPlots.update(stub, [plot("a"), plot("b"), plot("margin")])
    assert [h.title for h in stub.plots] == ["a", "b", "margin"]
    assert stub.plot_shapes == [_plot_shape(plot(t)) for t in ("a", "b", "margin")]
    assert [s["label"] for s in stub.plots[1].series[1:]] == ["b"]
    removed = stub.plots[2]
    AnalysisPlots.update(stub, [plot("a"), plot("b")])
    assert removed.removed and len(stub.plots) == 2
