"""The smaller command-line items of issue 24: input the lab must refuse with one line (status 2)
instead of a traceback, a hang or a non-finite metric."""

import math
import os

import pytest

from app.cli import main
from app.commands.headless import non_finite, stop_statuses
from lab_modules.exercises import get, registry


def _one_line_error(capsys, argv) -> str:
    assert main(argv) == 2
    out, err = capsys.readouterr()
    assert out == "" and len(err.splitlines()) == 1 and err.startswith("error: "), err
    return err


@pytest.mark.parametrize("seconds", ["nan", "-1", "1e9", "inf", "two"])
def test_bench_seconds_out_of_range_is_one_line(capsys, seconds):
    assert "--seconds" in _one_line_error(capsys, ["bench", "--seconds", seconds])


def test_data_from_a_fifo_is_refused_not_waited_for(tmp_path, capsys):
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    assert "is a pipe or socket" in _one_line_error(capsys, ["run", "maglev_tuning", "--data", str(fifo)])


@pytest.mark.parametrize("text", ["١٠", "１０", "1_0", "+1_0.5"])
def test_only_digits_0_to_9_are_numbers(capsys, text):
    assert "digits 0-9 only" in _one_line_error(capsys, ["run", "kalman_noise", "--set", f"gain_factor={text}"])


def test_a_duration_too_short_for_the_metrics_is_refused(capsys):
    """ekf_disturbance's force step comes at 0.05 s: a 0.05 s run measured nothing after it."""
    error = _one_line_error(capsys, ["run", "ekf_disturbance", "--duration", "0.05"])
    assert f"expected {get('ekf_disturbance').min_duration_s:g} ... 60 s" in error


def test_every_exercise_has_finite_metrics_at_its_shortest_run():
    for exercise in registry().values():
        assert exercise.min_duration_s <= exercise.default_duration_s, exercise.name
        metrics = exercise.metrics(exercise.resolve({}), exercise.min_duration_s)
        assert not non_finite(metrics) or stop_statuses(metrics), (exercise.name, non_finite(metrics))


@pytest.mark.parametrize("ki", [0.0, 1e-320, 1e-12])
def test_thrust_liftoff_without_integral_action_has_finite_noise_figures(ki):
    """An integral gain of (almost) zero leaves the PID's integrator at z = 1, reached by no noise:
    the predicted noise ratio is the limit Ki -> 0, not a singular-matrix traceback or NaN."""
    exercise = get("thrust_liftoff")
    predicted = exercise.metrics(exercise.resolve({"ki_a_per_mm_s": ki}), 0.3)["steady_std_ratio_predicted"]
    at_small_gain = exercise.metrics(exercise.resolve({"ki_a_per_mm_s": 1e-6}), 0.3)["steady_std_ratio_predicted"]
    assert math.isfinite(predicted) and predicted == pytest.approx(at_small_gain, rel=1e-6)
