"""Export for a lab report and the filter inspector, headless.

The exported scope CSV holds the scope window sample for sample with units in
its header; the readouts CSV the shown readouts; the chart PNGs are images.
The inspector's numbers (``Simulation.filter_state`` after ``advance(1)``)
equal filterpy's KalmanFilter run on the same measurements (kalman_noise), and
every filter's P is symmetric positive semi-definite."""

from __future__ import annotations

import csv
import re
import threading
from types import SimpleNamespace

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter as FilterpyKalman

from app.panels import export, inspector
from app.panels.export import ExportButtons
from app.panels.text import readout_rows
from app.tab.state import window_rows
from lab_modules.exercises import get, registry

#: the exercises with a Kalman filter in their browser simulation (maglev_tuning replays a
#: precomputed observer run that keeps each sample's prior)
FILTERED = ("kalman_noise", "ekf_parameters", "ekf_disturbance", "lqg_vs_pid", "maglev_tracking", "thrust_liftoff",
            "adaptive_filter", "maglev_tuning")


class _Client:
    def __init__(self):
        self.files: list[tuple[str, bytes]] = []

    def send_file_download(self, filename, content, save_immediately=False):
        self.files.append((filename, content))


def _session(name: str, code: str | None = "KN-7Q3M") -> SimpleNamespace:
    """What the export reads of a tab: a scope buffer exactly one window long."""
    exercise = get(name)
    values = exercise.resolve({})
    simulation = exercise.simulation(values)
    session = SimpleNamespace(exercise=exercise, values=values, simulation=simulation, lock=threading.Lock(),
                              columns={c: 1 + i for i, c in enumerate(simulation.columns)},
                              autosave_code=code, client=_Client(), closed=False)
    session.window = window_rows(values, simulation.sample_time_s)
    simulation.advance(200)                                   # the window is not the run's start
    session.buffer = simulation.advance(session.window)
    result = exercise.analyse(dict(values))
    session.shown_analysis = result if not hasattr(result, "__next__") else next(result)
    trace = {c: session.buffer[:, j] for c, j in session.columns.items()}
    session.export = ExportButtons(exercise, lambda: (session.buffer.copy(), dict(values), tuple(session.columns),
                                                      code),
                                   lambda: readout_rows(session.shown_analysis, exercise, trace),
                                   session.client.send_file_download)
    return session


def _csv_body(content: bytes) -> tuple[list[str], list[list[str]]]:
    lines = [line for line in content.decode().splitlines() if not line.startswith("#")]
    rows = list(csv.reader(lines))
    return rows[0], rows[1:]


@pytest.mark.parametrize("name", ["kalman_noise", "maglev_tracking", "lqg_vs_pid"])
def test_scope_csv_is_the_scope_window_with_units(name):
    session = _session(name)
    session.export.send_scope()
    (filename, content), = session.client.files
    assert re.fullmatch(rf"{name}_KN-7Q3M_\d{{8}}-\d{{6}}_scope\.csv", filename)
    header, rows = _csv_body(content)
    assert header[0] == "time_s [s]"
    assert [h.split(" [")[0] for h in header[1:]] == list(session.simulation.columns)
    assert all(re.fullmatch(r"\S+ \[[^\]]+\]", h) for h in header)
    assert len(rows) == session.window == len(session.buffer)
    np.testing.assert_array_equal(np.array(rows, dtype=float), session.buffer)   # every digit kept
    assert f"# exercise: {name}" in content.decode()


def test_units_read_from_column_names():
    charts = get("stiffness_map").charts
    assert export.column_unit("x_true_m") == "m"
    assert export.column_unit("velocity_true_m_per_s") == "m/s"
    assert export.column_unit("kx_true_n_per_m") == "N/m"
    assert export.column_unit("ki_true_n_per_a") == "N/A"
    assert export.column_unit("current_reference_v") == "V"
    assert export.column_unit("x_true_m_lqg") == "m"
    assert export.column_unit("nis") == "1"
    assert export.column_unit("k_magnet_estimate", charts) == next(
        c.unit for c in charts for s in c.series if s.column == "k_magnet_estimate")


def test_readouts_csv_holds_the_shown_readouts():
    session = _session("kalman_noise", code=None)
    session.export.send_readouts()
    (filename, content), = session.client.files
    assert re.fullmatch(r"kalman_noise_\d{8}-\d{6}_readouts\.csv", filename)   # no code: no code part
    header, rows = _csv_body(content)
    assert header == ["quantity", "value", "unit"]
    expected = session.export.readout_rows()
    assert len(rows) == len(expected) > len(session.shown_analysis.readouts)   # with the scope window's
    for (label, value, unit), row in zip(expected, rows):
        assert row[0] == label and row[2] == unit
        if isinstance(value, str):                    # a word readout ("computing …") as shown
            assert row[1] == value
        else:
            assert float(row[1]) == value or (np.isnan(value) and np.isnan(float(row[1])))


def test_each_chart_exports_as_a_png():
    session = _session("kalman_noise")
    for chart in session.exercise.charts:
        session.export.send_chart(chart)
    assert len(session.client.files) == len(session.exercise.charts)
    for (filename, content), chart in zip(session.client.files, session.exercise.charts):
        assert filename.endswith(f"_{re.sub('[^a-z0-9]+', '-', chart.title.lower())}.png")
        assert content[:8] == b"\x89PNG\r\n\x1a\n" and len(content) > 10_000


def test_inspector_matches_filterpy_on_kalman_noise():
    """N samples in two calls (N − 1, then one step); filterpy runs eq. 2 on the same
    measurements and inputs: x̂, P, K, innovation and √S agree."""
    exercise = get("kalman_noise")
    values = exercise.resolve({})
    simulation = exercise.simulation(values)
    n = 400
    trace = np.vstack([simulation.advance(n - 1), simulation.advance(1)])
    state = simulation.filter_state()

    rng = np.random.default_rng(int(values["seed"]))             # the simulation's noise, drawn alike
    noise = np.vstack([rng.standard_normal((n - 1, 4), dtype=np.float32),
                       rng.standard_normal((1, 4), dtype=np.float32)]).astype(float)
    setup, kf = simulation.setup, simulation.filter
    dim = kf.dim_x
    K_mx, K_mi = setup.rig.position_sensor_gain_v_per_m, setup.rig.current_sensor_gain_v_per_a
    measured_x, current, command = trace[:, 2], trace[:, 5], trace[:, 6]
    y = np.column_stack([K_mx * measured_x, K_mi * current + setup.noise_sigma[3] * noise[:, 3]])
    reference = FilterpyKalman(dim_x=dim, dim_z=2)
    reference.F, reference.B = kf.A[:dim, :dim], kf.B[:dim, None]
    reference.H, reference.Q, reference.R = kf.C[:, :dim], kf.Q[:dim, :dim], np.diag(kf.R_diag)
    reference.x = np.zeros(dim)
    reference.P = np.diag([(10e-6) ** 2, (1e-3) ** 2, 0.1**2, (10e-6) ** 2][:dim])   # AxisSimulation's P0
    for k in range(n):
        if k:
            reference.predict(u=np.array([command[k - 1]]))
        reference.update(y[k])

    def close(a, b):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-9 * np.max(np.abs(b)))

    close(state["x"], reference.x)
    close(state["P"], reference.P)
    close(state["K"], reference.K)
    close(state["innovation"], reference.y)
    close(state["innovation_sigma"], np.sqrt(np.diag(reference.S)))
    assert state["x"][0] == pytest.approx(trace[-1, 3], rel=1e-12)    # the scope's estimate column
    assert state["time_s"] == pytest.approx(trace[-1, 0])


def test_single_steps_run_the_same_loop():
    """Stepping sample by sample gives the trace of one long advance."""
    exercise = get("kalman_noise")
    values = exercise.resolve({})
    whole = exercise.simulation(values).advance(30)
    stepped = exercise.simulation(values)
    steps = np.vstack([stepped.advance(1) for _ in range(30)])
    np.testing.assert_allclose(steps, whole, rtol=1e-12, atol=1e-18)


@pytest.mark.parametrize("name", FILTERED)
def test_filter_state_everywhere(name):
    exercise = get(name)
    simulation = exercise.simulation(exercise.resolve({}))
    assert inspector.available(simulation)
    simulation.advance(300)
    assert simulation.filter_state() is None                  # a running loop keeps nothing extra
    row = simulation.advance(1)[0]
    state = simulation.filter_state()
    n, m = len(state["states"]), len(state["measurements"])
    P = state["P"]
    assert P.shape == (n, n) and state["x"].shape == (n,)
    np.testing.assert_allclose(P, P.T, rtol=0, atol=1e-12 * np.abs(P).max())
    assert np.linalg.eigvalsh(P).min() >= -1e-9 * np.abs(P).max()
    assert np.all(np.diag(P) > 0)
    if state["K"] is not None:
        assert state["K"].shape == (n, m) and np.all(state["innovation_sigma"] > 0)
    columns = ("time_s",) + tuple(simulation.columns)
    feedback = simulation.loop.setup.feedback if name == "adaptive_filter" else None
    estimate = next(c for c in ("x_estimated_m", "x_estimated_m_lqg", f"{feedback}_x_m") if c in columns)
    assert state["x"][0] == pytest.approx(row[columns.index(estimate)], rel=1e-9, abs=1e-15)
    text = inspector.markdown(state, simulation.sample_time_s)
    assert "±σ" in text and "Correlations" in text


def test_every_filtered_exercise_is_inspectable():
    offered = {name for name, exercise in registry().items()
               if inspector.available(exercise.simulation(exercise.resolve({})))}
    assert set(FILTERED) <= offered


def test_prefixes_keep_value_and_sigma_in_one_unit():
    assert inspector.prefixed(2.0e-7, "m") == (1e-9, "nm")
    assert inspector.prefixed(0.0148, "m") == (1e-3, "mm")
    assert inspector.prefixed(6.6e5, "N/m") == (1e3, "kN/m")
    assert inspector.gain_unit(0.14, "m", "m") == (1.0, "")
    assert inspector.gain_unit(108.0, "m/s", "m") == (1.0, "1/s")
    assert inspector.gain_unit(1.1e-6, "m", "V") == (1e-6, "µm/V")


def test_markdown_reads_like_a_table():
    exercise = get("thrust_liftoff")
    simulation = exercise.simulation(exercise.resolve({}))
    simulation.advance(100)
    simulation.advance(1)
    text = inspector.markdown(simulation.filter_state(), simulation.sample_time_s)
    assert "(sample 100)" in text and "| collar position x |" in text and "ν/√S" in text
    assert sum(line.startswith("|---") for line in text.splitlines()) == 4   # x̂, ρ, K, innovation tables


def test_maglev_tuning_replay_inspects_the_observer_it_replays():
    """The replayed run keeps each sample's prior: the correction redone from it gives the
    estimate, σ, innovation and √S columns the scope replays, at any sample."""
    exercise = get("maglev_tuning")
    simulation = exercise.simulation(exercise.resolve({}))
    columns = ("time_s",) + tuple(simulation.columns)
    for ahead in (0, 1234, 37):
        simulation.advance(ahead)
        row = simulation.advance(1)[0]
        state = simulation.filter_state()
        P = state["P"]
        np.testing.assert_allclose(P, P.T, rtol=0, atol=1e-15 * np.abs(P).max())
        assert np.linalg.eigvalsh(P).min() >= -1e-9 * np.abs(P).max()
        for k, name in enumerate(("x_estimated_m", "velocity_estimated_m_per_s", "current_estimated_a")):
            assert state["x"][k] == pytest.approx(row[columns.index(name)], rel=1e-9, abs=1e-15)
        for k, name in ((1, "velocity_sigma_m_per_s"), (2, "current_sigma_a")):
            assert np.sqrt(P[k, k]) == pytest.approx(row[columns.index(name)], rel=1e-6)
        assert state["innovation"][0] == pytest.approx(row[columns.index("innovation_m")], rel=1e-9, abs=1e-15)
        assert state["innovation_sigma"][0] == pytest.approx(row[columns.index("innovation_sigma_m")], rel=1e-9)
        assert state["K"].shape == (3, 1) and state["time_s"] == row[0]
