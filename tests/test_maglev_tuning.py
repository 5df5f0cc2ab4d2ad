"""Recordings and offline tuning of the maglev EKF (paper 004 §3.4-3.5):
CSV validation, the shipped recording's provenance, eq. 3.3's noise estimate,
NIS consistency and innovation whiteness, and the two exercises' metrics."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lab_modules import recordings
from lab_modules.exercises import maglev_tracking, maglev_tuning
from lab_modules.loops.maglev_loop import record_lead_lag_run
from lab_modules.parameters import ParameterError

ROOT = Path(__file__).resolve().parents[1]
TUNING = maglev_tuning.EXERCISE
HEADER = "time_s,reference_mm,measured_position_mm,coil_voltage_v\n"


def rows(n=20, start=0):
    return "".join(f"{(start + k) * 1e-3:.3f},14.8,14.80{k % 10},22.35\n" for k in range(n))


# -- recordings ------------------------------------------------------------------------

def test_round_trip_keeps_values_and_metadata():
    rec = record_lead_lag_run(duration_s=0.3, still_s=0.1, seed=3)
    back = recordings.parse("r.csv", recordings.to_csv(rec).encode())
    np.testing.assert_allclose(back.time_s, rec.time_s, atol=5e-4)
    np.testing.assert_allclose(back.measured_m, rec.measured_m, atol=5e-9)
    np.testing.assert_allclose(back.coil_voltage_v, rec.coil_voltage_v, atol=5e-4)
    assert back.metadata["sensor_noise_mm"] == "0.0034"


@pytest.mark.parametrize("content, expected", [
    ("time_s,reference_mm,measured_position_mm\n" + "0,14.8,14.8\n" * 20, "missing column(s) coil_voltage_v"),
    (HEADER + rows(5) + "0.005,14.8,abc,22.3\n" + rows(10, 6), "line 7, column measured_position_mm: 'abc'"),
    (HEADER + rows(5) + "0.004,14.8,14.8,22.3\n" + rows(10, 6), "line 7, column time_s: time 0.004 s does not"),
    (HEADER + rows(5) + "0.005,14.8,nan,22.3\n" + rows(10, 6), "column measured_position_mm: 'nan' is not a finite"),
    (HEADER + rows(5) + "0.005,14.8,14.8\n", "line 7: 3 fields, expected 4"),
    (HEADER + rows(3), "3 data rows; at least 10"),
    ("# only a comment\n", "no header line"),
])
def test_bad_files_get_one_line_errors(content, expected):
    with pytest.raises(ParameterError) as error:
        TUNING.load_data("bad.csv", content.encode())
    message = str(error.value)
    assert expected in message and "\n" not in message and message.startswith("bad.csv")


def test_huge_and_binary_files_are_refused():
    huge = (HEADER + rows(10)).encode() + b"0" * recordings.MAX_BYTES
    with pytest.raises(ParameterError, match="larger than 20 MB"):
        TUNING.load_data("huge.csv", huge)
    with pytest.raises(ParameterError, match="not a UTF-8 text file"):
        TUNING.load_data("x.csv", b"\xff\xfe\x00garbage")


def test_shipped_recording_is_the_stated_lab_run():
    """The shipped CSV is what scripts/make_maglev_recording.py writes (provenance), small, noise stated."""
    sys.path.insert(0, str(ROOT / "scripts"))
    from make_maglev_recording import SHIPPED, SHIPPED_SETTINGS
    assert SHIPPED.stat().st_size < 300_000
    regenerated = recordings.to_csv(record_lead_lag_run(**SHIPPED_SETTINGS)).splitlines()
    shipped = SHIPPED.read_text(encoding="utf-8").splitlines()
    differing = [i + 1 for i, (a, b) in enumerate(zip(regenerated, shipped, strict=True)) if a != b]
    assert not differing, f"shipped recording differs from a fresh run from line {differing[0]}"


# -- offline tuning ---------------------------------------------------------------------

def tuning_metrics(**overrides):
    return TUNING.metrics(TUNING.resolve(overrides), TUNING.default_duration_s)


def test_sensor_noise_recovered_within_10_percent():
    """Eq. 3.3 on the still segment recovers the recording's stated 0.0034 mm within 10 %;
    a window over the levitated part is inflated by the ball's motion."""
    m = tuning_metrics()
    assert m["estimated_sensor_noise_mm"] == pytest.approx(m["stated_sensor_noise_mm"], rel=0.10)
    moving = tuning_metrics(still_start_s=2.0, still_end_s=6.0)
    assert moving["estimated_sensor_noise_mm"] > 3 * m["stated_sensor_noise_mm"]


@pytest.mark.parametrize("overrides", [{"q_preset": "nis_tuned"},
                                       {"q_preset": "custom", "q_velocity": 1.5e-4}])
def test_tuned_q_is_consistent(overrides):
    """With a tuned Q the mean NIS lies inside its chi-square 95 % bounds, about 95 % of the
    100-sample windows do, and the innovations are white (autocorrelation inside ±1.96/√N
    at >= 85 % of lags 1-50)."""
    m = tuning_metrics(**overrides)
    assert m["mean_nis_inside_bounds"], m["mean_nis"]
    assert m["nis_within_95_percent"] >= 85.0
    assert m["innovation_whiteness_percent"] >= 85.0


@pytest.mark.parametrize("preset", ["eq_3.4", "table_3.1"])
def test_paper_q_values_are_inconsistent_on_this_recording(preset):
    """The paper's Q's belong to other data: both leave the NIS far below 1 (pessimistic filter)."""
    m = tuning_metrics(q_preset=preset)
    assert not m["mean_nis_inside_bounds"]
    assert m["mean_nis"] < 0.7 and m["nis_within_95_percent"] < 50.0


def test_too_small_q_is_overconfident():
    m = tuning_metrics(q_preset="custom", q_velocity=1e-6)
    assert m["mean_nis"] > 1.1 and not m["mean_nis_inside_bounds"]


def test_empty_still_segment_is_a_parameter_error():
    with pytest.raises(ParameterError, match="still segment 100 ... 200 s: start and end must lie inside the "
                                             "recording's 0 ... 6 s"):
        tuning_metrics(still_start_s=100.0, still_end_s=200.0)
    with pytest.raises(ParameterError, match="still segment 1 ... 1.001 s holds 1 samples"):
        tuning_metrics(still_start_s=1.0, still_end_s=1.001)


def test_replay_plays_the_observer_output_then_stops():
    values = TUNING.resolve({"q_preset": "nis_tuned"})
    replay = TUNING.simulation(values)
    first = replay.advance(4000)
    rest = replay.advance(4000)
    assert first.shape == (4000, 1 + len(replay.columns)) and rest.shape[0] == 2000
    assert "End of the recording" in replay.status_message()
    analysis = TUNING.analyse(values)
    assert {p.title.split(" ")[0] for p in analysis.plots} >= {"Innovation", "NIS", "Covariance"}


# -- headless runs (CLI contract) --------------------------------------------------------

def cli(*args):
    return subprocess.run([sys.executable, "-m", "app", *args], check=False, cwd=ROOT, capture_output=True,
                          text=True, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}, timeout=120)


def test_cli_tuning_with_data_file(tmp_path):
    """--data FILE.csv feeds a recording; a bad one fails with one line and exit code 2."""
    path = tmp_path / "run.csv"
    recordings.write(path, record_lead_lag_run(duration_s=3.0, still_s=1.0, sensor_noise_m=5e-6, seed=9))
    done = cli("run", "maglev_tuning", "--data", str(path), "--set", "q_preset=nis_tuned", "--json")
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result["metrics"]["estimated_sensor_noise_mm"] == pytest.approx(0.005, rel=0.1)
    assert result["parameters"]["data"] == str(path)
    path.write_text(HEADER + rows(5) + "0.004,14.8,14.8,22.3\n" + rows(10, 6))
    bad = cli("run", "maglev_tuning", "--data", str(path))
    assert bad.returncode == 2 and bad.stderr.strip().count("\n") == 0 and "line 7" in bad.stderr


def test_cli_tracking_metrics():
    """The headless tracking run reports the issue's metrics with Table 3.1's settings."""
    done = cli("run", "maglev_tracking", "--json")
    assert done.returncode == 0, done.stderr
    m = json.loads(done.stdout)["metrics"]
    np.testing.assert_allclose(m["feedback_gain"], [480000, 18800, 240], rtol=1e-9)
    assert m["step_tracking_rms_error_mm"] < 0.6 and m["sine_tracking_rms_error_mm"] < 0.6
    assert m["position_error_within_3sigma_percent"] >= 97.0
    assert m["velocity_error_within_3sigma_percent"] >= 97.0


def test_tracking_analysis_plots_and_guard_curve():
    values = maglev_tracking.EXERCISE.resolve({})
    analysis = maglev_tracking.EXERCISE.analyse(values)
    step_plot, voltage_plot = analysis.plots
    assert step_plot.series[0][1][-1] == pytest.approx(2.0, rel=0.01)      # the loop settles on 2 mm
    voltages = voltage_plot.series[0][1]
    assert voltages[0] > 10 * voltages[np.argmin(np.abs(voltage_plot.x - 0.894))]


def test_recording_downloaded_from_the_tracking_exercise_loads_into_the_tuning_exercise():
    """The browser's "Record a lead-lag run" button hands the student a CSV that
    ``maglev_tuning`` accepts, and eq. 3.3 recovers the chosen sensor noise."""
    tracking, tuning = maglev_tracking.EXERCISE, maglev_tuning.EXERCISE
    filename, content = tracking.download(tracking.resolve({"sensor_noise_mm": "0.01", "seed": "3"}))
    assert filename.endswith(".csv") and "0.01" in filename
    values = tuning.resolve({"data": tuning.load_data(filename, content)})
    metrics = tuning.metrics(values, tuning.default_duration_s)
    assert metrics["estimated_sensor_noise_mm"] == pytest.approx(0.01, rel=0.10)


@pytest.mark.parametrize("overrides", [{}, {"r_source": "slider", "filter_sensor_noise_mm": 1.0}])
def test_small_mean_nis_stays_in_view(overrides):
    """Issue 11, defect 13: a pessimistic filter's windowed mean NIS (1e-5 … 1e-3 here) is drawn on
    the log axis beside the χ² bounds 0.74 … 1.30, not cut off below the chart's 4-decade floor."""
    from app.panels.plots import plot_chart as _plot_chart
    from lab_modules.exercises import get

    exercise = get("maglev_tuning")
    plot = next(p for p in exercise.analyse(exercise.resolve(overrides)).plots if p.title.startswith("NIS"))
    means = plot.series[0][1]
    assert np.nanmin(means) < 1e-3                                   # the case of the defect
    y = _plot_chart(plot)[1]["scales"]["y"]
    assert y["distr"] == 3                                           # logarithmic
    assert y["min"] <= np.nanmin(means) and y["max"] >= plot.series[2][1][0]
    # every decade labelled legibly: uPlot's own numbers (three decimals) read "0" below 0.001
    axis = _plot_chart(plot)[1]["axes"][1]
    labels = dict(zip(axis["splits"], axis["values"]))
    assert labels[1e-4] == "10⁻⁴" and labels[1e-3] == "0.001" and labels[1.0] == "1"
    assert "0" not in axis["values"] and all(labels[10.0**k] for k in range(-4, 1))
