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

from app.margins import margin_view
from lab_modules import analysis
from lab_modules.exercises import get
from lab_modules.exercises.kalman_noise import setup


def _direct_sensitivity_peak(loop: control.StateSpace, omega: np.ndarray) -> float:
    A, B, C, D = (np.asarray(M) for M in (loop.A, loop.B, loop.C, loop.D))
    z = np.exp(1j * omega * loop.dt) if loop.dt else 1j * omega
    identity = np.eye(A.shape[0])
    L = np.array([(C @ np.linalg.solve(zk * identity - A, B) + D)[0, 0] for zk in z])
    return float(np.max(1.0 / np.abs(1.0 + L)))


def test_textbook_loop_agrees_with_control_margin():
    loop = control.ss(control.tf([4.0], [1.0, 3.0, 2.0, 0.0]))   # 4 / (s (s + 1) (s + 2))
    gm, pm, _, wcp = control.margin(loop)
    m = analysis.loop_margins(loop, np.logspace(-2, 2, 2000))
    assert m.gain_margin == pytest.approx(gm, rel=0.01)
    assert m.phase_margin_deg == pytest.approx(pm, rel=0.01)
    assert m.gain_crossover_rad_s == pytest.approx(wcp, rel=0.01)
    assert m.sensitivity_peak == pytest.approx(_direct_sensitivity_peak(loop, np.logspace(-2, 2, 20000)), rel=0.01)


@pytest.mark.parametrize("feedback", ["measured", "estimated"])
def test_bearing_loop_margins_bracket_stability(feedback):
    axis = setup(get("kalman_noise").resolve({"feedback": feedback}))
    loop = axis.loop_at_plant_input()
    m = analysis.loop_margins(loop)

    def stable(g: float) -> bool:
        return bool(np.max(np.abs(control.feedback(g * loop, 1).poles())) < 1.0)
    assert m.stable and stable(1.0)
    for margin in (m.gain_margin, m.gain_margin_down):
        assert stable(margin * 0.99 if margin > 1 else margin * 1.01)
        assert not stable(margin * 1.01 if margin > 1 else margin * 0.99)
    # the broken loop closes to the exercise's loop: same spectral radius
    assert max(abs(control.feedback(loop, 1).poles())) == pytest.approx(
        max(abs(analysis.loop_poles(axis.loop()))), rel=1e-6)
    omega = analysis.frequency_grid(loop, points=20000)
    assert m.sensitivity_peak == pytest.approx(_direct_sensitivity_peak(loop, omega), rel=0.01)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        _, pm_frd, _, _ = control.margin(control.frd(loop, omega))
    assert m.phase_margin_deg == pytest.approx(pm_frd, rel=0.01)
    assert m.zone == analysis.iso_zone(m.sensitivity_peak)


def test_iso_zones_and_the_analysis_tab_view():
    assert [analysis.iso_zone(p) for p in (2.9, 3.5, 4.5, 5.5)] == ["A", "B", "C", "D"]
    readouts, plots, _ = margin_view(get("lqg_vs_pid"), get("lqg_vs_pid").resolve({}))
    labels = [label for label, _, _ in readouts]
    assert any("PID: |S|max (zone" in label for label in labels)
    assert len(plots) == 3 and all(p.log_x for p in plots)
    assert margin_view(get("maglev_tuning"), get("maglev_tuning").resolve({})) == ([], [], [])
