"""The lab tab's pole maps (no browser): the dominant view leaves out the fast,
well-damped poles and keeps the slow and the lightly damped ones; both maps
draw the imaginary axis and range over all the poles they show."""

from __future__ import annotations

import numpy as np

from app.panels.pole_map import charts as _pole_charts
from lab_modules.evaluation.poles import dominant_decay_rad_s

POLES = {"plant": np.array([-20000.0, -5000.0, -193.0, 193.0]),
         "loop": np.array([-235 + 1205j, -235 - 1205j, -24.0, -22 + 4461j, -22 - 4461j,
                           -500 + 5000j, -500 - 5000j])}     # damping 0.1: shown although fast


def _shown(data) -> tuple[np.ndarray, np.ndarray]:
    """Real and imaginary parts of the poles a chart draws (all series but the axis)."""
    x, sets = data[0], np.vstack(data[1:-1])
    rows, columns = np.nonzero(np.isfinite(sets))
    return x[columns], sets[rows, columns]


def test_dominant_map_leaves_out_the_fast_real_poles():
    assert dominant_decay_rad_s(POLES) == 2 * 235.0          # twice the median decay rate
    (dominant, options), (full, _) = _pole_charts(POLES)
    real, _ = _shown(dominant)
    assert sorted(np.round(real)) == [-500, -500, -235, -235, -193, -24, -22, -22, 193]
    real_all, _ = _shown(full)
    assert len(real_all) == sum(len(p) for p in POLES.values())
    assert "470 rad/s" in options["title"]


def test_maps_draw_the_imaginary_axis_and_cover_their_poles():
    for data, options in _pole_charts(POLES):
        x, axis = data[0], data[-1]
        assert np.all(x[np.isfinite(axis)] == 0.0) and np.isfinite(axis).sum() == 2
        _, imag = _shown(data)
        y = options["scales"]["y"]
        assert y["min"] < imag.min() and y["max"] > imag.max() and y["min"] < axis[np.isfinite(axis)].min()
        assert np.all(np.diff(x) >= 0)                         # uPlot needs a sorted x


def test_real_poles_only_get_a_finite_view():
    (_, options), _ = _pole_charts({"plant": np.array([-300.0, -50.0])})
    y = options["scales"]["y"]
    assert np.isfinite([y["min"], y["max"]]).all() and y["max"] > 0 > y["min"]
